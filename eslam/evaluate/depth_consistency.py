"""How well a trajectory agrees with the depth images it was computed from.

ATE compares a trajectory with a reference trajectory and so inherits the reference's
own errors. This check needs none: frame i's depth points, moved by the trajectory's
relative pose into frame j and projected, should land where frame j measured them:

    p = T_j^-1 T_i X_i(u),  (u', z') = project(p),  r = z' - D_j(u')

(X_i(u): pixel u of frame i back-projected with its depth; D_j: frame j's depth at the
nearest pixel). A pose pair that is off by a few millimetres moves these residuals by
as much. Two trajectories of the same frames (e.g. an estimate and its ground truth)
are compared on the same pixels: those seen by frame j under both, with |r| within
``inlier_m`` under both (occlusions, depth edges and sensor outliers drop out
alike). The figure per pair is the median |r| over those pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from eslam.geometry.camera import backproject_depth, project_points
from eslam.types import Intrinsics


def depth_residuals(
    source_depth: np.ndarray,
    target_depth: np.ndarray,
    intrinsics: Intrinsics,
    source_pose: np.ndarray,
    target_pose: np.ndarray,
    every: int = 4,
    scale: float = 1.0,
) -> np.ndarray:
    """Residual r (m; module formula) of every ``every``-th source pixel, NaN where none.

    Args:
        source_depth, target_depth: (H, W) metres, 0 = invalid.
        intrinsics: both images' camera.
        source_pose, target_pose: (4, 4) camera-to-world.
        every: pixel step in both directions.
        scale: multiplies both depths (a candidate depth scale; 1 = as measured).

    Returns:
        (N,) float64, one per subsampled source pixel: NaN where the source has no
        depth, the point falls outside the target image or behind it, or the target
        has no depth there.
    """
    depth = torch.from_numpy(np.asarray(source_depth, np.float64))
    points = backproject_depth(depth, intrinsics)[::every, ::every].reshape(-1, 3)
    valid = depth[::every, ::every].reshape(-1) > 0
    relative = torch.from_numpy(np.linalg.inv(target_pose) @ source_pose)
    moved = scale * points @ relative[:3, :3].T + relative[:3, 3]
    uv, z = project_points(moved, intrinsics, torch.eye(4, dtype=torch.float64))
    u, v = uv[:, 0].round().long(), uv[:, 1].round().long()
    height, width = target_depth.shape
    inside = valid & (z > 0.1) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    target = torch.from_numpy(np.asarray(target_depth, np.float64))
    observed = torch.zeros_like(z)
    observed[inside] = target[v[inside], u[inside]] * scale
    residual = torch.full_like(z, float("nan"))
    seen = inside & (observed > 0)
    residual[seen] = z[seen] - observed[seen]
    return residual.numpy()


@dataclass(frozen=True)
class PairConsistency:
    """Median |depth residual| of one frame pair under each of several trajectories.

    Attributes:
        medians: (K,) metres, one per trajectory, over the same pixels.
        pixels: how many pixels every trajectory saw within the inlier bound.
    """

    medians: np.ndarray
    pixels: int


def pair_consistency(
    source_depth: np.ndarray,
    target_depth: np.ndarray,
    intrinsics: Intrinsics,
    poses: list[tuple[np.ndarray, np.ndarray]],
    inlier_m: float = 0.05,
    every: int = 4,
) -> PairConsistency:
    """Median |r| of a frame pair under each (source pose, target pose) in ``poses``,
    over the pixels whose |r| is within ``inlier_m`` under all of them (module text).

    Returns medians of NaN (and 0 pixels) when no pixel qualifies.
    """
    residuals = np.stack(
        [
            depth_residuals(source_depth, target_depth, intrinsics, source, target, every)
            for source, target in poses
        ]
    )
    common = np.all(np.abs(np.nan_to_num(residuals, nan=np.inf)) < inlier_m, axis=0)
    if not common.any():
        return PairConsistency(np.full(len(poses), np.nan), 0)
    medians = np.median(np.abs(residuals[:, common]), axis=1)
    return PairConsistency(medians, int(common.sum()))
