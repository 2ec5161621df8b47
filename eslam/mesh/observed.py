"""Observed space: which world points some keyframe saw (docs/method.md section 6).

A point is observed by a keyframe when it lies in front of the camera, projects inside
the image (nearest pixel) onto a valid depth D, and its depth along the optical axis is
at most D + margin (the truncation T: the band just behind a measured surface is
observed too). Mesh extraction keeps only surfaces in observed space, so unobserved
space (behind walls, outside every frustum) produces no phantom surfaces.

Depth maps can stay in their compact storage (e.g. the keyframe store's uint16 codes):
only the pixels a point projects onto are read and scaled by ``depth_scale``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from eslam.geometry.camera import project_points
from eslam.types import Intrinsics


@dataclass(frozen=True, eq=False)
class ObservedViews:
    """The keyframes that define observed space.

    Attributes:
        poses: (K, 4, 4) camera-to-world poses (any float dtype and device).
        depths: (K, H, W) depth maps in units of ``depth_scale`` metres (0 = invalid);
            any numeric dtype, e.g. the keyframe store's uint16 codes, read lazily.
        intrinsics: the camera of every view.
        margin: how far behind the measured depth still counts as observed, metres.
        depth_scale: metres per depth unit (1.0 for float metres).
    """

    poses: torch.Tensor
    depths: torch.Tensor
    intrinsics: Intrinsics
    margin: float
    depth_scale: float = 1.0

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    def far_depths(self) -> np.ndarray:
        """(K,) float64 farthest observed depth of each view (max valid depth + margin), m."""
        far = [float(depth.to(torch.float32).max()) * self.depth_scale for depth in self.depths]
        return np.asarray(far, dtype=np.float64) + self.margin


def seen_by_view(points: torch.Tensor, views: ObservedViews, k: int) -> torch.Tensor:
    """(M,) bool: which of the (M, 3) world points view ``k`` observed.

    Computed on the depth maps' device; the result is on ``points``' device.
    """
    depth = views.depths[k]
    pose = views.poses[k].to(device=depth.device, dtype=torch.float32)
    intrinsics = views.intrinsics
    uv, z = project_points(points.to(device=depth.device, dtype=torch.float32), intrinsics, pose)
    u, v = uv[:, 0].round(), uv[:, 1].round()
    inside = (z > 0) & (u >= 0) & (u <= intrinsics.width - 1)
    inside &= (v >= 0) & (v <= intrinsics.height - 1)
    u = u.clamp(0, intrinsics.width - 1).long()
    v = v.clamp(0, intrinsics.height - 1).long()
    measured = depth[v, u].to(torch.float32) * views.depth_scale
    seen = inside & (measured > 0) & (z <= measured + views.margin)
    return seen.to(points.device)


def observed_mask(
    points: torch.Tensor, views: ObservedViews, candidates: list[int] | None = None
) -> torch.Tensor:
    """(M,) bool: whether any view observed each of the (M, 3) world points.

    Args:
        points: (M, 3) world points, metres.
        views: the keyframes.
        candidates: the view indices to test (default all); views that cannot see the
            points may be left out to save time.

    Only points not yet seen are tested against each further view, so the cost falls
    as points are found observed.
    """
    seen = torch.zeros(points.shape[0], dtype=torch.bool, device=points.device)
    order = range(len(views)) if candidates is None else candidates
    remaining = torch.arange(points.shape[0], device=points.device)
    for k in order:
        if remaining.numel() == 0:
            break
        hit = seen_by_view(points[remaining], views, k)
        seen[remaining[hit]] = True
        remaining = remaining[~hit]
    return seen


def views_seeing_boxes(lower: np.ndarray, upper: np.ndarray, views: ObservedViews) -> np.ndarray:
    """Conservative test of which views may observe part of each axis-aligned box.

    A box is ruled out for a view when all 8 of its corners lie outside one plane of
    the view's frustum (behind the camera, beyond the farthest observed depth, or past
    an image border); boxes that pass may still be unobserved.

    Args:
        lower, upper: (N, 3) box corners, metres.

    Returns:
        (N, K) bool.
    """
    corners = np.stack(
        [
            np.where(np.array([i, j, k], dtype=bool), upper, lower)
            for i in (0, 1)
            for j in (0, 1)
            for k in (0, 1)
        ],
        axis=1,
    )  # (N, 8, 3)
    intrinsics = views.intrinsics
    left = (-0.5 - intrinsics.cx) / intrinsics.fx
    right = (intrinsics.width - 0.5 - intrinsics.cx) / intrinsics.fx
    top = (-0.5 - intrinsics.cy) / intrinsics.fy
    bottom = (intrinsics.height - 0.5 - intrinsics.cy) / intrinsics.fy
    far = views.far_depths()
    poses = views.poses.detach().to("cpu", torch.float64).numpy()
    result = np.zeros((lower.shape[0], len(views)), dtype=bool)
    for k, pose in enumerate(poses):
        local = (corners - pose[:3, 3]) @ pose[:3, :3]  # camera frame, (N, 8, 3)
        x, y, z = local[..., 0], local[..., 1], local[..., 2]
        outside = (
            (z <= 0).all(1)
            | (z > far[k]).all(1)
            | (x < left * z).all(1)
            | (x > right * z).all(1)
            | (y < top * z).all(1)
            | (y > bottom * z).all(1)
        )
        result[:, k] = ~outside
    return result


def observed_box(views: ObservedViews) -> tuple[np.ndarray, np.ndarray]:
    """(3,) lower and (3,) upper corners of a box holding every view's observed space.

    Each view sees at most its image pyramid from the camera centre out to its farthest
    observed depth; the box holds all those pyramids' corners.
    """
    intrinsics = views.intrinsics
    far = views.far_depths()
    us = np.array([-0.5, intrinsics.width - 0.5])
    vs = np.array([-0.5, intrinsics.height - 0.5])
    rays = np.array(
        [
            [(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0]
            for u in us
            for v in vs
        ]
    )  # (4, 3), unit z
    poses = views.poses.detach().to("cpu", torch.float64).numpy()
    centres = poses[:, :3, 3]
    ends = np.einsum("kij,rj->kri", poses[:, :3, :3], rays) * far[:, None, None]
    points = np.concatenate([centres, (ends + centres[:, None]).reshape(-1, 3)])
    return points.min(0), points.max(0)
