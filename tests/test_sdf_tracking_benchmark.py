"""benchmarks/sdf_tracking.py: its reference poses (ground truth or the run's own
trajectory.txt) and the frames it tracks."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from eslam.io.trajectory import read_trajectory, write_tum_trajectory
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "sdf_tracking.py"


@pytest.fixture(scope="module")
def script():
    return load_script(SCRIPT)


def _measure(script, run: Path, *extra: str):
    return script.measure(script.parse_args([str(run), "--no-append", *extra]))


def test_estimate_poses_come_from_the_runs_trajectory(script, tiny_run, tmp_path: Path) -> None:
    """Tracked on the run's own map from the run's own previous pose, each frame lands
    near the run's pose (1.6 cm on this 80x60 toy map); with every pose of trajectory.txt
    moved 5 cm (the map not), the reference is 5 cm off the map and the error says so."""
    window = ("--poses", "estimate", "--first", "4", "--frames", "3")
    rows, tracked = _measure(script, tiny_run.run_dir, *window)
    assert list(tracked) == [4, 5, 6]
    own = rows[0].error_mm
    assert own < 25.0
    moved = tmp_path / "moved"
    shutil.copytree(tiny_run.run_dir, moved)
    times, poses = read_trajectory(tiny_run.run_dir)
    poses[:, 0, 3] += 0.05
    write_tum_trajectory(moved / "trajectory.txt", times, poses)
    rows_moved, _ = _measure(script, moved, *window)
    assert rows_moved[0].error_mm > own + 25.0


def test_truth_poses_are_the_sequences_ground_truth(script, tiny_run) -> None:
    """The default reference is the ground truth: the tiny run's estimate differs from it,
    so the two references give different errors on the same frames."""
    truth, tracked = _measure(script, tiny_run.run_dir, "--frames", "3")
    estimate, _ = _measure(script, tiny_run.run_dir, "--poses", "estimate", "--frames", "3")
    assert list(tracked) == [1, 2, 3]
    assert truth[0].error_mm != pytest.approx(estimate[0].error_mm, abs=1e-3)
    assert np.isfinite(truth[0].information_min) and truth[0].information_min > 0


def test_frames_past_the_run_are_refused(script, tiny_run) -> None:
    with pytest.raises(SystemExit, match="no frames to track from --first 50"):
        _measure(script, tiny_run.run_dir, "--poses", "estimate", "--first", "50")
