"""The keyframe pose graph (eslam.slam.loops.pose_graph) against hand-computed cases."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from eslam.errors import ConfigError
from eslam.slam.loops.pose_graph import Edge, carry_poses, relative_pose, solve_pose_graph
from eslam.slam.session import run_slam
from tests.conftest import tiny_config

pytest.importorskip("gtsam", reason="the loops extra (GTSAM) is not installed")


def _pose(x: float = 0.0, y: float = 0.0, yaw_deg: float = 0.0) -> np.ndarray:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    pose = np.eye(4)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:2, 3] = x, y
    return pose


def _edge(a: int, b: int, relative: np.ndarray, robust: bool = False) -> Edge:
    return Edge(a, b, relative, sigma_rotation=0.01, sigma_translation=0.01, robust=robust)


def test_a_loop_spreads_the_disagreement_evenly() -> None:
    """Odometry 0->1 and 1->2 each say 1 m along x, a loop 0->2 says 2.3 m, all with
    equal sigmas: minimising (x1 - 1)^2 + (x2 - x1 - 1)^2 + (x2 - 2.3)^2 with x0 = 0
    gives x1 = 1.1, x2 = 2.2 (each edge off by 0.1 m)."""
    start = np.stack([_pose(0.0), _pose(1.0), _pose(2.0)])
    edges = [_edge(0, 1, _pose(1.0)), _edge(1, 2, _pose(1.0)), _edge(0, 2, _pose(2.3))]
    solution = solve_pose_graph(start, edges)
    np.testing.assert_allclose(solution.poses[:, 0, 3], [0.0, 1.1, 2.2], atol=1e-6)
    np.testing.assert_allclose(solution.poses[:, :3, :3], np.tile(np.eye(3), (3, 1, 1)), atol=1e-9)
    np.testing.assert_allclose(
        solution.edge_residuals, [10.0, 10.0, 10.0], rtol=1e-4
    )  # 0.1 m / 1 cm
    assert solution.error_after < solution.error_before


def test_anchors_keep_the_correction_near_the_loop() -> None:
    """The same graph with a prior on nodes 1 and 2 at their given poses (sigma as the
    edges'): minimising the sum above plus (x1 - 1)^2 + (x2 - 2)^2 gives 3 x1 - x2 = 1
    and 3 x2 - x1 = 5.3, so x1 = 1.0375, x2 = 2.1125: node 1, two edges from the loop's
    far end, moves a third of node 2's shift instead of half."""
    start = np.stack([_pose(0.0), _pose(1.0), _pose(2.0)])
    edges = [_edge(0, 1, _pose(1.0)), _edge(1, 2, _pose(1.0)), _edge(0, 2, _pose(2.3))]
    solution = solve_pose_graph(start, edges, anchor=(0.01, 0.01))
    np.testing.assert_allclose(solution.poses[:, 0, 3], [0.0, 1.0375, 2.1125], atol=1e-6)
    np.testing.assert_allclose(solution.poses[:, :3, :3], np.tile(np.eye(3), (3, 1, 1)), atol=1e-9)


def test_a_square_with_yaw_drift_closes() -> None:
    """Four 1 m sides with 90 degree turns; odometry measures 91 degrees per turn, so the
    chain ends 4 degrees and some centimetres off; the loop edge (the true 4->0 side)
    brings every corner back within a few millimetres and a tenth of a degree."""
    truth = np.stack([_pose(0, 0, 0), _pose(1, 0, 90), _pose(1, 1, 180), _pose(0, 1, 270)])
    step = _pose(1.0, 0.0, 91.0)
    chain = [np.eye(4)]
    for _ in range(3):
        chain.append(chain[-1] @ step)
    edges = [_edge(i, i + 1, step) for i in range(3)]
    edges.append(_edge(3, 0, relative_pose(truth[3], truth[0])))
    solution = solve_pose_graph(np.stack(chain), edges)
    before = np.linalg.norm(np.stack(chain)[:, :3, 3] - truth[:, :3, 3], axis=1).max()
    after = np.linalg.norm(solution.poses[:, :3, 3] - truth[:, :3, 3], axis=1).max()
    assert before > 0.03 and after < 0.015


def test_a_robust_loop_edge_cannot_bend_the_trajectory() -> None:
    """A false loop says node 4 is back at the start; four odometry edges say 1 m each.
    Without the kernel the end moves about 2 m; with it, under 5 cm, and its residual
    shows it was overruled."""
    start = np.stack([_pose(float(i)) for i in range(5)])
    odometry = [_edge(i, i + 1, _pose(1.0)) for i in range(4)]
    for robust, bound in ((False, None), (True, 0.05)):
        solution = solve_pose_graph(start, [*odometry, _edge(0, 4, _pose(0.0), robust)])
        moved = abs(solution.poses[4, 0, 3] - 4.0)
        if bound is None:
            assert moved > 1.5
        else:
            assert moved < bound
            assert solution.edge_residuals[-1] > 100.0


def test_frames_move_with_their_node() -> None:
    before = np.stack([_pose(0.0), _pose(1.0)])
    after = np.stack([_pose(0.0), _pose(1.0, 0.5, 30.0)])
    frame = _pose(1.2, 0.1, 5.0)
    moved = carry_poses(frame[None], np.array([1]), before, after)[0]
    np.testing.assert_allclose(relative_pose(after[1], moved), relative_pose(before[1], frame))


def test_bad_edges_and_a_missing_gtsam_are_named(
    monkeypatch: pytest.MonkeyPatch, tiny_sequence: Path, tmp_path: Path
) -> None:
    start = np.stack([_pose(0.0), _pose(1.0)])
    with pytest.raises(ValueError, match=r"edge \(0, 2\)"):
        solve_pose_graph(start, [_edge(0, 2, _pose(1.0))])
    monkeypatch.setitem(sys.modules, "gtsam", None)
    with pytest.raises(ConfigError, match=r'pip install "eslam\[loops\]"'):
        solve_pose_graph(start, [_edge(0, 1, _pose(1.0))])
    # a run with loop closure on is refused before its folder is written
    with pytest.raises(ConfigError, match="needs GTSAM"):
        run_slam(tiny_config(tiny_sequence, "mapping.loops.enabled=true"), tmp_path / "run")
    assert not (tmp_path / "run").exists()
