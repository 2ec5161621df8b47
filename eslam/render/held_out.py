"""Held-out depth L1 of a field: how well a map predicts frames it was not fitted to.

Used to score the first mapping call (``benchmarks/first_frame.py`` and its test): a
field fitted to frame 0 is looked at from the ground-truth poses of later frames: the
depth of its surface along their pixels' rays, and its TSDF at their measured points.

Only pixels whose surface point the fitted frame observed are scored (``observed_by``):
a map cannot know surfaces its frame never saw, and counting them buries the
differences between schedules under a constant error of the unobserved parts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from eslam.geometry.camera import backproject_depth, project_points
from eslam.render.rays import camera_directions
from eslam.render.renderer import SceneFieldLike
from eslam.render.sampling import ray_box_intersection
from eslam.render.surface import first_zero_crossing, interpolate_zero
from eslam.types import Frame

OBSERVED_TOLERANCE_M = 0.05
"""A point counts as observed by a frame when its depth there is within this of the
frame's measured depth at the pixel it projects to (metres)."""


def observed_mask(
    points_world: torch.Tensor, frame: Frame, tolerance: float = OBSERVED_TOLERANCE_M
) -> torch.Tensor:
    """Which world points ``frame`` saw: visible in its image, not occluded.

    A point p is observed when it projects (pinhole, :func:`project_points`) inside the
    image of ``frame`` at its ground-truth pose, in front of the camera, onto a pixel
    with valid depth d (nearest pixel), and its own depth z there satisfies
    |z - d| <= ``tolerance``.

    Args:
        points_world: (N, 3) points.
        frame: a frame with ``pose_gt``.

    Returns:
        (N,) bool.
    """
    if frame.pose_gt is None:
        raise ValueError(f"frame {frame.index} has no ground-truth pose")
    c2w = torch.from_numpy(frame.pose_gt).to(points_world.dtype)
    uv, z = project_points(points_world, frame.intrinsics, c2w)
    width, height = frame.intrinsics.width, frame.intrinsics.height
    column = torch.round(uv[:, 0]).long()
    row = torch.round(uv[:, 1]).long()
    inside = (z > 0) & (column >= 0) & (column < width) & (row >= 0) & (row < height)
    depth = torch.from_numpy(frame.depth).to(points_world.dtype)
    measured = depth[row.clamp(0, height - 1), column.clamp(0, width - 1)]
    return inside & (measured > 0) & ((z - measured).abs() <= tolerance)


SURFACE_STEP = 0.25
"""Step of the zero-crossing search along a ray, in units of the truncation."""


def surface_depth(
    field: SceneFieldLike, origins: torch.Tensor, directions: torch.Tensor, chunk: int = 4096
) -> torch.Tensor:
    """(N,) depth of the first zero crossing of the TSDF along each ray (nan: none).

    The ray is marched from its entry into the field's bound box (clamped to the
    origin) to its exit in steps of ``SURFACE_STEP`` truncations; at the first sample
    pair going from s > 0 to s <= 0 the depth is interpolated linearly,
    z = z_a + (z_b - z_a) s_a / (s_a - s_b). This is the depth of the surface the mesh
    would show (the marching-cubes level set), without the bias of volume rendering.

    Args:
        origins: (N, 3) world ray origins.
        directions: (N, 3) world directions with unit camera z (depth = ray parameter).
    """
    step = SURFACE_STEP * field.truncation
    depths = []
    for at in range(0, len(origins), chunk):
        o, d = origins[at : at + chunk], directions[at : at + chunk]
        near, far = ray_box_intersection(o, d, field.bound)
        count = int(((far - near).clamp_min(0).max() / step).ceil()) + 1
        z = near[:, None] + step * torch.arange(count, dtype=o.dtype, device=o.device)
        inside = z <= far[:, None]
        points = o[:, None, :] + z[..., None] * d[:, None, :]
        sdf = field.query(points.reshape(-1, 3), with_rgb=False).sdf.reshape(z.shape)
        sdf = torch.where(inside, sdf, torch.ones_like(sdf))
        index, hit = first_zero_crossing(z, sdf)
        first = index[:, None]
        s_a, s_b = sdf.gather(1, first)[:, 0], sdf.gather(1, first + 1)[:, 0]
        z_a = z.gather(1, first)[:, 0]
        depth = interpolate_zero(z_a, z_a + step, s_a, s_b)
        depths.append(torch.where(hit, depth, torch.full_like(depth, float("nan"))))
    return torch.cat(depths)


@dataclass(frozen=True)
class HeldOutErrors:
    """How well a field predicts frames it was not fitted to.

    Attributes:
        depth_l1_m: mean |surface depth - measured depth|, metres, over the pixels whose
            ray meets the map's surface (:func:`surface_depth`).
        missed: share of the scored pixels whose ray meets no surface of the map.
        surface_sdf_m: mean |T s(p)| at the measured surface points p, metres: the SDF
            tracker's residual at the true pose (0 for a perfect map).
        pixels: pixels scored.
    """

    depth_l1_m: float
    missed: float
    surface_sdf_m: float
    pixels: int


def held_out_errors(
    field: SceneFieldLike,
    frames: Sequence[Frame],
    *,
    observed_by: Frame | None = None,
    pixel_step: int = 1,
) -> HeldOutErrors:
    """:class:`HeldOutErrors` over the valid pixels of ``frames`` at their true poses.

    Every ``pixel_step``-th valid pixel is scored, and with ``observed_by`` only those
    whose measured surface point that frame observed (:func:`observed_mask`).

    The depth is that of the map's surface, not a volume-rendered one: ESLAM's density
    is not zero in free space nor symmetric about the surface, so rendered depth is
    biased (rendered without measured depth it comes out short, the more so the more
    samples a ray takes), and the bias hides the differences between maps.

    Raises:
        ValueError: a frame lacks a ground-truth pose, or no pixel is left to score.
    """
    depth_errors, sdf_errors = [], []
    with torch.no_grad():
        for frame in frames:
            if frame.pose_gt is None:
                raise ValueError(f"frame {frame.index} has no ground-truth pose")
            pose = torch.from_numpy(frame.pose_gt).float()
            depth = torch.from_numpy(frame.depth)
            pixels = torch.nonzero(depth.reshape(-1) > 0).squeeze(1)[::pixel_step]
            points = backproject_depth(depth, frame.intrinsics, pose).reshape(-1, 3)
            if observed_by is not None:
                pixels = pixels[observed_mask(points[pixels], observed_by)]
            if len(pixels) == 0:
                continue
            directions = camera_directions(frame.intrinsics)[pixels] @ pose[:3, :3].T
            origins = pose[:3, 3].expand_as(directions)
            found = surface_depth(field, origins, directions)
            depth_errors.append((found - depth.reshape(-1)[pixels]).abs())
            sdf = field.query(points[pixels], with_rgb=False).sdf
            sdf_errors.append(sdf.abs() * field.truncation)
    if not depth_errors:
        raise ValueError("no held-out pixel to score")
    depth_error = torch.cat(depth_errors)
    hit = torch.isfinite(depth_error)
    return HeldOutErrors(
        depth_l1_m=float(depth_error[hit].mean()) if bool(hit.any()) else float("nan"),
        missed=float((~hit).float().mean()),
        surface_sdf_m=float(torch.cat(sdf_errors).mean()),
        pixels=len(depth_error),
    )
