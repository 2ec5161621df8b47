"""Scene bounds from depth: the box the observed points occupy, and what lies outside one.

Pure functions on tensors (any float dtype and device). A bound is a (3, 2) tensor
[[xmin, xmax], [ymin, ymax], [zmin, zmax]] in metres, world frame of the poses.
Robustness: boxes are taken between low and high percentiles of the points, so a few
far outliers (depth spikes, windows) neither blow a box up nor trigger growth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from eslam.geometry.camera import backproject_depth
from eslam.types import Intrinsics

MAX_BOUND_POINTS = 10_000
"""Points back-projected per depth map at most: the image is subsampled on a regular grid."""
BOUND_PERCENTILE = 0.5
"""Percentile (per side, per axis) of points left out of a box as outliers: 0.5 and 99.5."""


@dataclass(frozen=True, eq=False)
class BoundCoverage:
    """How well a bound covers a set of points.

    Attributes:
        fraction_outside: share of the points outside the bound, in [0, 1] (0 for no points).
        required: (3, 2) the smallest box holding the bound and the points' robust box
            (percentiles :data:`BOUND_PERCENTILE`), grown by the margin where it had to
            grow; equal to the bound when the robust box already fits inside.
        grows: whether ``required`` is larger than the bound on some side.
    """

    fraction_outside: float
    required: torch.Tensor
    grows: bool


def subsample_stride(height: int, width: int, max_points: int = MAX_BOUND_POINTS) -> int:
    """Pixel step s (rows and columns) so that ceil(H / s) * ceil(W / s) <= ``max_points``."""
    if max_points < 1:
        raise ValueError(f"max_points must be >= 1, got {max_points}")
    stride = max(1, math.ceil(math.sqrt(height * width / max_points)))
    while math.ceil(height / stride) * math.ceil(width / stride) > max_points:
        stride += 1
    return stride


def depth_points(
    depth: torch.Tensor,
    intrinsics: Intrinsics,
    c2w: torch.Tensor,
    max_points: int = MAX_BOUND_POINTS,
    max_depth: float | None = None,
) -> torch.Tensor:
    """World points of the valid pixels of a depth map, subsampled on a regular grid.

    Args:
        depth: (H, W) depth along the optical axis, metres; 0, negative or non-finite
            values are invalid.
        intrinsics: the camera of ``depth``.
        c2w: (4, 4) camera-to-world pose.
        max_points: at most this many pixels are back-projected (before masking).
        max_depth: optional cap, metres: deeper pixels are ignored.

    Returns:
        (N, 3) world points, dtype of ``depth``; N = 0 when no pixel is valid.
    """
    if depth.ndim != 2 or tuple(depth.shape) != (intrinsics.height, intrinsics.width):
        raise ValueError(
            f"depth must be ({intrinsics.height}, {intrinsics.width}), got {tuple(depth.shape)}"
        )
    stride = subsample_stride(intrinsics.height, intrinsics.width, max_points)
    points = backproject_depth(depth, intrinsics, c2w)[::stride, ::stride].reshape(-1, 3)
    sampled = depth[::stride, ::stride].reshape(-1)
    valid = torch.isfinite(sampled) & (sampled > 0)
    if max_depth is not None:
        valid &= sampled <= max_depth
    return points[valid]


def robust_box(points: torch.Tensor, percentile: float = BOUND_PERCENTILE) -> torch.Tensor:
    """(3, 2) per-axis [percentile, 100 - percentile] box of ``points`` (N, 3), N >= 1."""
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"points must be (N, 3) with N >= 1, got {tuple(points.shape)}")
    if not 0.0 <= percentile < 50.0:
        raise ValueError(f"percentile must be in [0, 50), got {percentile}")
    q = torch.tensor([percentile / 100.0, 1.0 - percentile / 100.0], dtype=points.dtype)
    return torch.quantile(points, q.to(points.device), dim=0).T.contiguous()


def estimate_bound(
    points: torch.Tensor,
    margin: float,
    centres: torch.Tensor | None = None,
    percentile: float = BOUND_PERCENTILE,
) -> torch.Tensor:
    """A scene box from observed points: their robust box, plus camera centres, plus margin.

    Args:
        points: (N, 3) observed world points, metres, N >= 1.
        margin: metres added on every side (>= 0).
        centres: optional (M, 3) camera centres the box must also hold (the rays
            between camera and surface are sampled, so the free space must be inside).
        percentile: outlier share left out per side and axis, percent.

    Returns:
        (3, 2) [[xmin, xmax], [ymin, ymax], [zmin, zmax]], dtype of ``points``.
    """
    if margin < 0:
        raise ValueError(f"margin must be >= 0, got {margin}")
    box = robust_box(points, percentile)
    if centres is not None:
        centres = centres.to(box).reshape(-1, 3)
        box = torch.stack(
            (torch.minimum(box[:, 0], centres.amin(0)), torch.maximum(box[:, 1], centres.amax(0))),
            dim=1,
        )
    return box + torch.tensor([-margin, margin], dtype=box.dtype, device=box.device)


def fraction_outside(points: torch.Tensor, bound: torch.Tensor) -> float:
    """Share of (N, 3) ``points`` outside the (3, 2) ``bound`` (0 when N = 0)."""
    if len(points) == 0:
        return 0.0
    bound = bound.to(points)
    inside = ((points >= bound[:, 0]) & (points <= bound[:, 1])).all(dim=1)
    return 1.0 - float(inside.float().mean())


def bound_coverage(
    points: torch.Tensor,
    bound: torch.Tensor,
    margin: float,
    percentile: float = BOUND_PERCENTILE,
) -> BoundCoverage:
    """The share of ``points`` outside ``bound`` and the box it must grow to.

    A side of the bound grows only where the points' robust box crosses it, and then
    to the robust box's side plus ``margin``; the other sides keep their value.

    Args:
        points: (N, 3) world points, metres.
        bound: (3, 2) current scene box, metres.
        margin: metres beyond the points' robust box on a side that grows.
        percentile: outlier share left out per side and axis, percent.
    """
    bound = bound.detach()
    if len(points) == 0:
        return BoundCoverage(0.0, bound.clone(), False)
    box = robust_box(points.detach().to(bound), percentile)
    low = torch.where(box[:, 0] < bound[:, 0], box[:, 0] - margin, bound[:, 0])
    high = torch.where(box[:, 1] > bound[:, 1], box[:, 1] + margin, bound[:, 1])
    required = torch.stack((low, high), dim=1)
    grown = bool((low < bound[:, 0]).any() or (high > bound[:, 1]).any())
    return BoundCoverage(fraction_outside(points, bound), required, grown)


def union_box(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(3, 2) the smallest box holding the (3, 2) boxes ``a`` and ``b``."""
    b = b.to(a)
    return torch.stack((torch.minimum(a[:, 0], b[:, 0]), torch.maximum(a[:, 1], b[:, 1])), dim=1)
