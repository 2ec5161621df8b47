"""benchmarks/loop_edges.py: a loop edge at the truth is closer than a drifted estimate,
and one the estimate already holds is not; measured odometry edges are read from a
run's map.pt; a run without loops gets one line, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from eslam.io.checkpoint import save_checkpoint
from eslam.io.trajectory import RUN_TRAJECTORY, RUN_TRAJECTORY_GT, write_tum_trajectory
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "loop_edges.py"


def _pose(x: float, yaw_deg: float) -> np.ndarray:
    angle = np.radians(yaw_deg)
    pose = np.eye(4)
    pose[:3, :3] = [
        [np.cos(angle), 0, np.sin(angle)],
        [0, 1, 0],
        [-np.sin(angle), 0, np.cos(angle)],
    ]
    pose[0, 3] = x
    return pose


def _run(folder: Path, estimate: np.ndarray, truth: np.ndarray, loops: list[dict]) -> Path:
    folder.mkdir()
    times = np.arange(len(truth), dtype=float)
    write_tum_trajectory(folder / RUN_TRAJECTORY, times, estimate)
    write_tum_trajectory(folder / RUN_TRAJECTORY_GT, times, truth)
    (folder / "loops.json").write_text(json.dumps(loops))
    return folder


def test_edges_at_the_truth_are_closer_than_a_drifted_estimate(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    truth = np.stack([_pose(0.01 * k, 2.0 * k) for k in range(400)])
    drift = np.stack([_pose(0.012 * k, 2.1 * k) for k in range(400)])
    exact = np.linalg.inv(truth[0]) @ truth[350]
    held = np.linalg.inv(drift[100]) @ drift[150]
    loops = [
        {"frame": 350, "candidate_frame": 0, "relative_pose": exact.tolist(), "accepted": True},
        {"frame": 150, "candidate_frame": 100, "relative_pose": held.tolist(), "accepted": True},
        {"frame": 200, "candidate_frame": 0, "relative_pose": None, "accepted": False},
    ]
    for entry, inliers in zip(loops, (0.9, 0.7, 0.3), strict=True):
        entry["inlier_fraction"] = inliers
    run = _run(tmp_path / "on", truth, truth, loops)
    off = _run(tmp_path / "off", drift, truth, [])
    errors = script.edge_errors(script.accepted_loops(run), drift, truth)
    assert errors.shape == (2, 5)
    (gap, edge_cm, edge_deg, est_cm, est_deg), second = errors
    assert gap == 350 and edge_cm < 1e-6 and edge_deg < 1e-4
    assert est_cm > 50 and est_deg > 30
    assert np.allclose(second[1:3], second[3:5])
    assert script.main([str(run), "--estimate", str(off)]) == 0
    out = capsys.readouterr().out
    assert "| 2 | all |" in out and "| 1 of 2 |" in out and "| 1 | >= 300 |" in out
    assert [i for i, _, _ in script.accepted_loops(run, min_inliers=0.8)] == [350]
    assert script.main([str(run), "--estimate", str(off), "--min-inliers", "0.8"]) == 0
    assert "| 1 | all |" in capsys.readouterr().out


def test_a_run_without_loops_or_of_other_frames_is_refused(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    truth = np.stack([_pose(0.01 * k, 0.0) for k in range(20)])
    bare = _run(tmp_path / "bare", truth, truth, [])
    (bare / "loops.json").unlink()
    assert script.main([str(bare)]) == 2
    assert "loops.json: missing" in capsys.readouterr().err
    empty = _run(tmp_path / "empty", truth, truth, [])
    assert script.main([str(empty)]) == 2
    assert "no accepted loop" in capsys.readouterr().err
    loop = {"frame": 15, "candidate_frame": 0, "relative_pose": np.eye(4).tolist()}
    loop["inlier_fraction"] = 0.9
    run = _run(tmp_path / "run", truth, truth, [dict(loop, accepted=True)])
    short = _run(tmp_path / "short", truth[:10], truth[:10], [])
    assert script.main([str(run), "--estimate", str(short)]) == 2
    assert "10 poses, not 20" in capsys.readouterr().err


def test_measured_odometry_edges_are_judged_from_the_map(tmp_path: Path, capsys) -> None:
    """Two edges kept (one at the truth, one off by 3 cm) and one refused (None)."""
    script = load_script(SCRIPT)
    truth = np.stack([_pose(0.01 * k, 1.0 * k) for k in range(20)])
    exact = np.linalg.inv(truth[0]) @ truth[4]
    off = np.linalg.inv(truth[4]) @ truth[8]
    off[0, 3] += 0.03
    record = {"0-4": exact.ravel().tolist(), "4-8": off.ravel().tolist(), "8-12": None}
    run = _run(tmp_path / "run", truth, truth, [])
    save_checkpoint(run / "map.pt", {"components": {"loops": {"odometry": record}}})
    edges = script.measured_odometry(run)
    assert [(i, j) for i, j, _ in edges] == [(4, 0), (8, 4)]
    errors = script.edge_errors(edges, truth, truth)
    assert errors[0, 1] < 1e-6 and abs(errors[1, 1] - 3.0) < 1e-6
    assert script.main([str(run), "--odometry"]) == 0
    assert "| 2 | all |" in capsys.readouterr().out
    with pytest.raises(SystemExit) as stop:
        script.main([str(run), "--odometry", "--min-inliers", "0.9"])
    assert stop.value.code == 2 and "--min-inliers" in capsys.readouterr().err
    save_checkpoint(run / "map.pt", {"components": {}})
    assert script.main([str(run), "--odometry"]) == 2
    assert "holds no measured odometry edges" in capsys.readouterr().err
