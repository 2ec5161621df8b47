"""benchmarks/start_shift.py: the frames the map moved far from their start, and
their steps."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from eslam.io.trajectory import write_tum_trajectory
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "start_shift.py"


def _walk(count: int) -> np.ndarray:
    poses = np.tile(np.eye(4), (count, 1, 1))
    poses[:, 0, 3] = 0.01 * np.arange(count)
    return poses


def _timings(count: int) -> dict:
    """Frame 0 not judged; frames 1-7 from features (400 matches, 5 mm), except frame
    3 (moved 8 cm, overruled), frame 5 (moved 9 cm with 100 matches) and frame 6
    (moved 7 cm, kept the map's pose)."""
    matches = [None] + [400.0] * (count - 1)
    shifts = [None] + [0.005] * (count - 1)
    overruled = [None] + [0.0] * (count - 1)
    shifts[3], overruled[3] = 0.08, 1.0
    shifts[5], matches[5] = 0.09, 100.0
    shifts[6] = 0.07
    return {
        "tracking_start_matches": matches,
        "tracking_start_shift_m": shifts,
        "tracking_overruled": overruled,
        "tracking_inlier_fraction": [None] + [0.8] * (count - 1),
    }


def test_the_frames_over_both_thresholds_and_their_steps() -> None:
    script = load_script(SCRIPT)
    truth = _walk(8)
    estimated = truth.copy()
    estimated[6:, 1, 3] += 0.07  # frame 6 kept the map's pose, 7 cm off (and 7 follows)
    report = script.shift_report(estimated, truth, _timings(8), matches=300, shift=0.05)
    assert report.picked == [3, 6] and report.overruled == [3]
    assert report.step_mm == pytest.approx([0.0, 70.0], abs=1e-6)
    assert report.picked_shift_mm == pytest.approx([80.0, 70.0])
    assert report.picked_inliers == pytest.approx([0.8, 0.8])
    assert report.from_features == 7
    assert report.shift_mm[2] == pytest.approx(90.0)
    assert report.other_step_mm == pytest.approx(0.0, abs=1e-6)


def test_a_run_prints_one_row(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    truth = _walk(8)
    stamps = np.arange(8, dtype=np.float64)
    write_tum_trajectory(tmp_path / "trajectory.txt", stamps, truth)
    write_tum_trajectory(tmp_path / "trajectory_gt.txt", stamps, truth)
    (tmp_path / "timings.json").write_text(json.dumps(_timings(8)))
    assert script.main([str(tmp_path)]) == 0
    assert (
        "| 2 (1 overruled) | 3*: 0 (8.0 cm, 80 %), 6: 0 (7.0 cm, 80 %) |" in capsys.readouterr().out
    )


def test_a_run_without_starts_from_features_is_one_line_and_status_2(
    tmp_path: Path, capsys
) -> None:
    script = load_script(SCRIPT)
    assert script.main([str(tmp_path)]) == 2
    assert "trajectory.txt: missing" in capsys.readouterr().err
    truth = _walk(3)
    for name in ("trajectory.txt", "trajectory_gt.txt"):
        write_tum_trajectory(tmp_path / name, np.arange(3.0), truth)
    (tmp_path / "timings.json").write_text(json.dumps({"tracking_s": [0.1, 0.1, 0.1]}))
    assert script.main([str(tmp_path)]) == 2
    assert "tracking.start: features" in capsys.readouterr().err
