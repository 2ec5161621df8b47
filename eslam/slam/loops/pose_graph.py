"""The keyframe pose graph: odometry and loop edges, solved with GTSAM.

Nodes are camera-to-world poses T_i (4x4, metres). An edge (a, b) measures the pose of
b in a's frame, Z_ab ~ T_a^-1 T_b, with independent Gaussian noise on the rotation
(radians, about each axis) and translation (metres) of the error
log(Z_ab^-1 T_a^-1 T_b) in se(3) (GTSAM's ``BetweenFactorPose3``: the tangent vector
orders rotation before translation). Loop edges may be robust: a Cauchy kernel whose
weight falls as 1 / (1 + (r / k)^2) for a whitened residual r, so one false loop cannot
bend the trajectory (Sunderhauf and Protzel, "Switchable constraints", 2012, compare
M-estimators for exactly this). One node is held fixed (a prior far tighter than any
edge) to remove the gauge freedom; the rest follow by Levenberg-Marquardt from the
given poses. Frames that are not nodes move with a node (:func:`carry_poses`): their
pose relative to it stays what it was.

GTSAM is an optional extra (``pip install "eslam[loops]"``), imported where used.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eslam.errors import ConfigError

FIXED_SIGMA = 1e-6
"""Sigma of the prior that holds the fixed node (rad and m): a gauge, not a measurement."""


@dataclass(frozen=True)
class Edge:
    """A relative-pose measurement between nodes ``a`` and ``b``.

    Attributes:
        a, b: node indices.
        relative: (4, 4) the pose of b in a's frame, T_a^-1 T_b.
        sigma_rotation: standard deviation of each rotation component, radians.
        sigma_translation: standard deviation of each translation component, metres.
        robust: weigh the edge with a Cauchy kernel of width ``robust_k`` (loop edges).
        robust_k: the kernel's width in whitened units (sigmas).
    """

    a: int
    b: int
    relative: np.ndarray
    sigma_rotation: float
    sigma_translation: float
    robust: bool = False
    robust_k: float = 1.0


@dataclass(frozen=True)
class GraphSolution:
    """The optimised poses and how well each edge agrees with them.

    Attributes:
        poses: (N, 4, 4) float64 camera-to-world poses.
        error_before / error_after: the graph's total cost (GTSAM's, half the sum of
            kernel-weighted squared whitened residuals) at the start and at the end.
        edge_residuals: (E,) each edge's whitened residual norm at the solution, in
            sigmas (before the kernel): a loop edge far above a few sigmas was overruled.
        iterations: Levenberg-Marquardt iterations taken.
    """

    poses: np.ndarray
    error_before: float
    error_after: float
    edge_residuals: np.ndarray
    iterations: int


def import_gtsam():
    """The gtsam module, or a ConfigError naming the extra that installs it."""
    try:
        import gtsam
    except ImportError as error:
        raise ConfigError(
            'loop closure needs GTSAM (pose graph): pip install "eslam[loops]"'
        ) from error
    return gtsam


def _noise(gtsam, edge: Edge):
    sigmas = np.array([edge.sigma_rotation] * 3 + [edge.sigma_translation] * 3, dtype=float)
    model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
    if edge.robust:
        kernel = gtsam.noiseModel.mEstimator.Cauchy.Create(edge.robust_k)
        model = gtsam.noiseModel.Robust.Create(kernel, model)
    return model


def solve_pose_graph(
    poses: np.ndarray,
    edges: Sequence[Edge],
    fixed: int = 0,
    max_iterations: int = 100,
    anchor: tuple[float, float] | None = None,
) -> GraphSolution:
    """Optimise the node poses ``poses`` (N, 4, 4) under ``edges``, node ``fixed`` held.

    ``anchor`` (rotation rad, translation m): every other node also has a prior at its
    pose as given, with these sigmas. A tracker that registers each frame to a global
    map measures each keyframe's pose against that map, not only against the keyframe
    before it: its error does not add up along the chain, and a loop's correction
    should stay near the loop instead of spreading along every odometry edge back to
    the fixed node. With priors of sigma s_a and odometry edges of sigma s_o a
    correction fades along the chain over about s_a / s_o nodes (a chain of springs
    tied to the ground); None = no priors (the correction spreads over the whole chain).

    Raises:
        ValueError: an edge names a node outside [0, N) or joins a node to itself.
        ConfigError: GTSAM is not installed.
    """
    gtsam = import_gtsam()
    poses = np.asarray(poses, dtype=np.float64)
    count = len(poses)
    for edge in edges:
        if not (0 <= edge.a < count and 0 <= edge.b < count) or edge.a == edge.b:
            raise ValueError(f"edge ({edge.a}, {edge.b}) does not join two of {count} nodes")
    graph = gtsam.NonlinearFactorGraph()
    graph.add(
        gtsam.PriorFactorPose3(
            fixed, gtsam.Pose3(poses[fixed]), gtsam.noiseModel.Isotropic.Sigma(6, FIXED_SIGMA)
        )
    )
    if anchor is not None:
        sigmas = np.array([anchor[0]] * 3 + [anchor[1]] * 3, dtype=float)
        prior = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        for index in range(count):
            if index != fixed:
                graph.add(gtsam.PriorFactorPose3(index, gtsam.Pose3(poses[index]), prior))
    for edge in edges:
        measured = gtsam.Pose3(np.asarray(edge.relative, dtype=np.float64))
        graph.add(gtsam.BetweenFactorPose3(edge.a, edge.b, measured, _noise(gtsam, edge)))
    initial = gtsam.Values()
    for index, pose in enumerate(poses):
        initial.insert(index, gtsam.Pose3(pose))
    parameters = gtsam.LevenbergMarquardtParams()
    parameters.setMaxIterations(max_iterations)
    optimiser = gtsam.LevenbergMarquardtOptimizer(graph, initial, parameters)
    result = optimiser.optimize()
    solved = np.stack([result.atPose3(i).matrix() for i in range(count)])
    residuals = np.array([_whitened(gtsam, edge, solved) for edge in edges])
    return GraphSolution(
        poses=solved,
        error_before=float(graph.error(initial)),
        error_after=float(graph.error(result)),
        edge_residuals=residuals,
        iterations=int(optimiser.iterations()),
    )


def _whitened(gtsam, edge: Edge, poses: np.ndarray) -> float:
    """|| log(Z^-1 T_a^-1 T_b) / sigma || of ``edge`` at ``poses``."""
    measured = gtsam.Pose3(np.asarray(edge.relative, dtype=np.float64))
    actual = gtsam.Pose3(poses[edge.a]).between(gtsam.Pose3(poses[edge.b]))
    error = gtsam.Pose3.Logmap(measured.between(actual))
    sigmas = np.array([edge.sigma_rotation] * 3 + [edge.sigma_translation] * 3)
    return float(np.linalg.norm(error / sigmas))


def relative_pose(pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """T_a^-1 T_b: the pose of b in a's frame (what an edge measures)."""
    return np.linalg.solve(np.asarray(pose_a, np.float64), np.asarray(pose_b, np.float64))


def carry_poses(
    frames: np.ndarray, anchor: np.ndarray, before: np.ndarray, after: np.ndarray
) -> np.ndarray:
    """Move each frame with its anchor node: T'_f = T'_n T_n^-1 T_f.

    Args:
        frames: (F, 4, 4) the frames' poses before the graph was solved.
        anchor: (F,) int, the node each frame moves with.
        before / after: (N, 4, 4) the nodes' poses before and after.
    """
    frames = np.asarray(frames, np.float64)
    moved = np.asarray(after, np.float64) @ np.linalg.inv(np.asarray(before, np.float64))
    return moved[np.asarray(anchor)] @ frames


def anchors(keyframe_frames: tuple[int, ...], count: int) -> np.ndarray:
    """(count,) for each frame 0..count-1 the latest keyframe at or before it (frames
    before the first keyframe: keyframe 0), the node it moves with."""
    latest = np.searchsorted(np.asarray(keyframe_frames), np.arange(count), side="right") - 1
    return np.maximum(latest, 0)
