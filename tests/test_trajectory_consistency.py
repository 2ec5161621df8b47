"""benchmarks/trajectory_consistency.py: finds a jump put into a ground truth, and its splice."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from eslam.io.trajectory import write_tum_trajectory
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing import write_sevenscenes_sequence
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "trajectory_consistency.py"
CONFIG = Path(__file__).resolve().parents[1] / "configs" / "sevenscenes" / "redkitchen.yaml"
JUMP_AT = 5


@pytest.fixture(scope="module")
def script():
    return load_script(SCRIPT)


def _jumped(poses: np.ndarray, at: int, metres: float) -> np.ndarray:
    """``poses`` with every pose from ``at`` on moved ``metres`` along its own view axis
    of frame ``at`` (a ground truth with one wrong step)."""
    step = np.eye(4)
    step[2, 3] = metres
    correction = poses[at] @ step @ np.linalg.inv(poses[at])
    moved = poses.copy()
    moved[at:] = correction @ poses[at:]
    return moved


def test_replaced_step_takes_one_motion_and_keeps_the_rest(script) -> None:
    frames = list(generate_sequence(SynthConfig(frames=8, width=32, height=24, seed=1)))
    truth = np.stack([f.pose_gt for f in frames])
    wrong = _jumped(truth, JUMP_AT, 0.04)
    spliced = script.replaced_step(wrong, truth, JUMP_AT)
    np.testing.assert_allclose(spliced, truth, atol=1e-12)
    np.testing.assert_allclose(script.replaced_step(truth, truth, JUMP_AT), truth, atol=1e-12)


def test_reports_the_injected_jump(script, tmp_path: Path, capsys) -> None:
    config = SynthConfig(frames=12, width=160, height=120, seed=4, step_translation=0.01)
    frames = list(generate_sequence(config))
    truth = np.stack([f.pose_gt for f in frames])
    wrong = _jumped(truth, JUMP_AT, 0.04)
    # The dataset's ground truth has the jump; the depth and "our estimate" do not.
    recorded = [dataclasses.replace(f, pose_gt=p) for f, p in zip(frames, wrong, strict=True)]
    write_sevenscenes_sequence(tmp_path / "seq", recorded)
    run = tmp_path / "run"
    run.mkdir()
    write_tum_trajectory(run / "trajectory.txt", np.arange(len(frames), dtype=float), truth)
    script.main(
        ["--config", str(CONFIG), "--data", str(tmp_path / "seq"), "--run", str(run),
         "--gaps", "1", "6", "12", "--step", "1", "--every", "2", "--no-append"]
    )  # fmt: skip
    out = capsys.readouterr().out
    steps = out.split("Single steps")[1].split("\n| ")
    assert steps[2].startswith(f"{JUMP_AT - 1} -> {JUMP_AT} | "), out  # the worst step
    # The ground truth with its worst step taken from the estimate is the estimate.
    estimate_ate = out.split("ATE RMSE of the estimate: ")[1].split(" cm")[0]
    floor = out.split("replaced by the estimate's scores ")[1].split(" cm")[0]
    assert floor == estimate_ate != "0.00"
    gap_six = next(line for line in out.splitlines() if line.startswith("| 6 |"))
    better, pairs = gap_six.split("|")[5].strip().split(" of ")
    # Pairs (0, 6) to (4, 10) cross the jump and favour the estimate; (5, 11) lies after
    # it, where both trajectories have the same relative pose (a tie rounding decides).
    assert pairs == "6" and int(better) >= 5
    assert "| 12 | 0 | - | - | - |" in out  # no pair that far apart: a row, not a crash
    # The ATE errors by place in the mapping cycle (12 frames, 3 per place) make up the ATE.
    cycle = out.split("i mod every |")[1].split("\n\n")[0].splitlines()[2:]
    by_place = np.array([float(row.strip("|").split("|")[4]) for row in cycle])
    assert len(by_place) == 4
    assert np.sqrt(np.mean(by_place**2)) == pytest.approx(float(estimate_ate), abs=0.01)


def test_segment_rows_locate_where_the_estimate_moves_too_far(script) -> None:
    frames = 21
    truth = np.tile(np.eye(4), (frames, 1, 1))
    truth[:, 0, 3] = 0.01 * np.arange(frames)  # 1 cm per frame along x
    estimate = truth.copy()
    estimate[10:, 0, 3] = 0.1 + 0.012 * np.arange(frames - 10)  # 20 % more from frame 10
    errors = np.linalg.norm(estimate[:, :3, 3] - truth[:, :3, 3], axis=1)
    medians = {0: np.array([0.004, 0.005]), 12: np.array([0.006, 0.003])}
    rows = script.segment_rows(estimate, truth, errors, medians, length=10, hop=2)
    cells = [[c.strip() for c in row.strip("|").split("|")] for row in rows]
    assert [c[0] for c in cells] == ["0-10", "10-20"]
    assert cells[0][1] == "0.00" and float(cells[1][1]) > 0.5
    assert cells[0][4] == "1.000" and cells[1][4] == "1.200"
    assert cells[0][2] == "10.0" and cells[1][3] == "12.0"
    assert cells[0][5:] == ["4.00", "5.00"] and cells[1][5:] == ["6.00", "3.00"]
    # A hop longer than a segment (a long first gap) measures no motion: no ratio.
    long_hop = script.segment_rows(estimate, truth, errors, {}, length=10, hop=11)
    assert [row.strip("|").split("|")[4].strip() for row in long_hop] == ["-", "-"]
