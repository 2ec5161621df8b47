"""benchmarks/depth_scale_check.py finds a known depth scale error, with the right sign."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "depth_scale_check.py"
GAP = 30


@pytest.fixture(scope="module")
def check():
    return load_script(SCRIPT)


@pytest.fixture(scope="module")
def pair():
    config = SynthConfig(frames=GAP + 1, width=160, height=120, seed=2, step_translation=0.02)
    frames = list(generate_sequence(config))
    return frames[0], frames[GAP]


@pytest.mark.parametrize("stored_over_true", [1.0, 1.04, 0.97])
def test_best_scale_undoes_the_error(check, pair, stored_over_true: float) -> None:
    source, target = (
        dataclasses.replace(f, depth=f.depth * np.float32(stored_over_true)) for f in pair
    )
    scales = np.round(np.arange(0.9, 1.1001, 0.005), 4)
    medians, baseline = check.pair_residuals(source, target, scales, 0.05, 2)
    assert baseline > 0.2
    best = scales[int(np.nanargmin(medians))]
    # depth stored k times too large fits best when multiplied by 1 / k
    assert best == pytest.approx(1.0 / stored_over_true, abs=0.006)
    if stored_over_true == 1.0:  # exact data: only the nearest-pixel lookup is left
        assert medians[int(np.argmin(np.abs(scales - 1.0)))] < 0.005
