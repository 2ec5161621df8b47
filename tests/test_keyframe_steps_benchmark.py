"""benchmarks/keyframe_steps.py: a run's per-frame error split at its keyframes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "keyframe_steps.py"


def _walk(count: int) -> np.ndarray:
    poses = np.tile(np.eye(4), (count, 1, 1))
    poses[:, 0, 3] = 0.01 * np.arange(count)
    return poses


def test_a_step_at_each_keyframe_shows_in_the_keyframe_pairs_only() -> None:
    script = load_script(SCRIPT)
    truth = _walk(13)
    estimated = truth.copy()
    keyframes = {0, 4, 8, 12}
    for k in (4, 8):  # refined keyframes 3 mm off, the frames around them not
        estimated[k, 1, 3] += 0.003
    errors = script.split_errors(estimated, truth, keyframes)
    mm, _, pairs = errors["rpe_keyframe"]
    assert pairs == 6 and mm == pytest.approx(3.0 * np.sqrt(4 / 6), abs=1e-9)  # 4 of 6 step
    assert errors["rpe_other"][0] == pytest.approx(0.0, abs=1e-9) and errors["rpe_other"][2] == 6
    assert errors["ate_keyframes"] > errors["ate_others"]
    assert errors["rpe"].translation_rmse * 1000 == pytest.approx(3.0 * np.sqrt(4 / 12))


def test_a_folder_without_a_run_is_one_line_and_status_2(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    assert script.main([str(tmp_path)]) == 2
    assert "trajectory.txt: missing" in capsys.readouterr().err
