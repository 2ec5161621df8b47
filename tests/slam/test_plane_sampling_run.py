"""A whole tiny run with the fused plane sampling (the default) tracks as the reference."""

from __future__ import annotations

import numpy as np

from eslam.slam.loop import run_slam
from tests.conftest import tiny_config


def test_fused_run_gives_the_reference_trajectory(tiny_sequence, tiny_run, tmp_path) -> None:
    assert tiny_config(tiny_sequence).field.plane_sampling == "fused"  # what tiny_run used
    reference = run_slam(
        tiny_config(tiny_sequence, "field.plane_sampling=reference"), tmp_path / "run"
    )
    # same maths, float32 rounding in another order (tests/field/test_fused_sampling.py
    # holds one query equal): over 12 frames of Adam steps and chained poses that grows to
    # millimetres (up to 3 mm on an AVX-512 CPU); a wrong sampling moves centimetres
    difference = np.abs(np.asarray(reference.poses) - np.asarray(tiny_run.poses)).max()
    assert difference < 5e-3, difference
    ate = reference.metrics["ate_rmse_cm"], tiny_run.metrics["ate_rmse_cm"]
    assert abs(ate[0] - ate[1]) < 0.05 * max(ate), ate
