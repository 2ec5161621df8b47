"""Pinhole camera maths: pixels to rays, depth to points, points to pixels.

Pixel (u, v) = (column, row), the centre of the top-left pixel at (0, 0). Camera axes
are OpenCV's (x right, y down, z forward). Ray directions in the camera frame have
unit z, so ``point = direction * depth`` for a depth measured along the optical axis.
All functions are pure and differentiable; they work in the dtype and on the device
of their tensor inputs.
"""

from __future__ import annotations

import torch

from eslam.types import Intrinsics


def pixel_grid(
    intrinsics: Intrinsics, dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu"
) -> torch.Tensor:
    """Pixel-centre coordinates of every pixel.

    Returns:
        uv: (H, W, 2) with uv[v, u] = (u, v).
    """
    u = torch.arange(intrinsics.width, dtype=dtype, device=device)
    v = torch.arange(intrinsics.height, dtype=dtype, device=device)
    vv, uu = torch.meshgrid(v, u, indexing="ij")
    return torch.stack((uu, vv), dim=-1)


def pixels_to_camera_directions(uv: torch.Tensor, intrinsics: Intrinsics) -> torch.Tensor:
    """Camera-frame ray directions with unit z through pixels ``uv``.

    d = ((u - cx) / fx, (v - cy) / fy, 1).

    Args:
        uv: (..., 2) pixel coordinates.

    Returns:
        (..., 3) directions in the camera frame, z = 1.
    """
    x = (uv[..., 0] - intrinsics.cx) / intrinsics.fx
    y = (uv[..., 1] - intrinsics.cy) / intrinsics.fy
    return torch.stack((x, y, torch.ones_like(x)), dim=-1)


def camera_to_world_rays(
    directions_cam: torch.Tensor, c2w: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Rotate camera-frame directions into the world and attach the camera centre.

    Args:
        directions_cam: (..., 3) camera-frame directions (unit z keeps depth semantics).
        c2w: (4, 4) camera-to-world pose, or (..., 4, 4) one pose per direction.

    Returns:
        origins (..., 3) and directions (..., 3) in world coordinates (not normalised).
    """
    rotation = c2w[..., :3, :3]
    directions = (rotation @ directions_cam.unsqueeze(-1)).squeeze(-1)
    origins = torch.broadcast_to(c2w[..., :3, 3], directions.shape)
    return origins, directions


def backproject_depth(
    depth: torch.Tensor, intrinsics: Intrinsics, c2w: torch.Tensor | None = None
) -> torch.Tensor:
    """3D points of every pixel of a depth map.

    Args:
        depth: (H, W) depth along the optical axis, metres (0 = invalid; such pixels
            give the camera centre and are for the caller to mask).
        c2w: optional (4, 4) camera-to-world pose; without it points are in the camera frame.

    Returns:
        (H, W, 3) points.
    """
    uv = pixel_grid(intrinsics, dtype=depth.dtype, device=depth.device)
    points = pixels_to_camera_directions(uv, intrinsics) * depth.unsqueeze(-1)
    if c2w is None:
        return points
    c2w = c2w.to(depth.dtype)
    return points @ c2w[:3, :3].T + c2w[:3, 3]


def project_points(
    points_world: torch.Tensor, intrinsics: Intrinsics, c2w: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Project world points into the image of a camera.

    u = fx * x / z + cx, v = fy * y / z + cy with (x, y, z) = R^T (p - t).

    Args:
        points_world: (..., 3) points.
        c2w: (4, 4) camera-to-world pose.

    Returns:
        uv (..., 2) pixel coordinates and z (...) depth along the optical axis (points with
        z <= 0 are behind the camera; their uv is meaningless).
    """
    rotation = c2w[:3, :3]
    points_cam = (points_world - c2w[:3, 3]) @ rotation
    z = points_cam[..., 2]
    safe_z = torch.where(z.abs() > 1e-12, z, torch.copysign(torch.full_like(z, 1e-12), z))
    u = intrinsics.fx * points_cam[..., 0] / safe_z + intrinsics.cx
    v = intrinsics.fy * points_cam[..., 1] / safe_z + intrinsics.cy
    return torch.stack((u, v), dim=-1), z
