"""Rays from pixels: which pixels to sample and the world rays through them.

Directions keep unit z in the camera frame (OpenCV axes), so ``origin + z * direction``
is the point at depth z along the optical axis. Pixels are indexed row-major:
index = v * W + u.
"""

from __future__ import annotations

import torch

from eslam.geometry.camera import camera_to_world_rays, pixel_grid, pixels_to_camera_directions
from eslam.types import Intrinsics, RayBatch


def sample_pixels(
    valid: torch.Tensor, count: int, border: int, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Draw pixels uniformly, with replacement, among valid pixels away from the border.

    A pixel (u, v) may be drawn when ``valid[v, u]`` and border <= v < H - border and
    border <= u < W - border (the release's crop: rows and columns ``border`` to
    ``H - border`` / ``W - border``, end excluded).

    Args:
        valid: (H, W) bool, e.g. pixels with a usable depth.
        count: number of pixels to draw.
        border: pixels at each image edge that are never drawn.
        generator: source of randomness, on the device of ``valid``.

    Returns:
        (count,) int64 flat row-major pixel indices.

    Raises:
        ValueError: when no valid pixel lies inside the border.
    """
    if valid.dim() != 2 or valid.dtype != torch.bool:
        raise ValueError(f"valid must be an (H, W) bool tensor, got {valid.dtype} {valid.shape}")
    if border < 0 or count < 0:
        raise ValueError(f"border and count must be >= 0, got border={border}, count={count}")
    height, width = valid.shape
    inside = torch.zeros_like(valid)
    inside[border : max(height - border, 0), border : max(width - border, 0)] = True
    candidates = torch.nonzero((valid & inside).reshape(-1)).squeeze(1)
    if candidates.numel() == 0:
        raise ValueError(
            f"no valid pixel at least {border} px from the border of the {width}x{height} "
            "image (is the depth map empty, or the border too wide?)"
        )
    pick = torch.randint(candidates.numel(), (count,), generator=generator, device=valid.device)
    return candidates[pick]


def camera_directions(
    intrinsics: Intrinsics,
    device: torch.device | str = "cpu",
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """Unit-z camera-frame directions through every pixel centre.

    d = ((u - cx) / fx, (v - cy) / fy, 1).

    Returns:
        (H * W, 3), row-major (index = v * W + u).
    """
    uv = pixel_grid(intrinsics, dtype=dtype, device=device)
    return pixels_to_camera_directions(uv, intrinsics).reshape(-1, 3)


def rays_from_pixels(
    directions_cam: torch.Tensor, c2w: torch.Tensor, depth: torch.Tensor, rgb: torch.Tensor
) -> RayBatch:
    """World rays of M pixels seen by camera(s) at ``c2w``; differentiable w.r.t. ``c2w``.

    origin = t, direction = R d_cam, with c2w = [R t; 0 1].

    Args:
        directions_cam: (M, 3) unit-z camera-frame directions.
        c2w: (4, 4) camera-to-world pose, or (M, 4, 4) one per ray.
        depth: (M,) measured depth along the optical axis, metres.
        rgb: (M, 3) measured colour in [0, 1].

    Returns:
        A RayBatch of M rays.
    """
    count = directions_cam.shape[0]
    if c2w.shape not in ((4, 4), (count, 4, 4)):
        raise ValueError(f"c2w must be (4, 4) or ({count}, 4, 4), got {tuple(c2w.shape)}")
    if depth.shape != (count,) or rgb.shape != (count, 3):
        raise ValueError(
            f"depth must be ({count},) and rgb ({count}, 3), "
            f"got {tuple(depth.shape)} and {tuple(rgb.shape)}"
        )
    origins, directions = camera_to_world_rays(directions_cam, c2w.to(directions_cam.dtype))
    return RayBatch(origins=origins, directions=directions, depth=depth, rgb=rgb)
