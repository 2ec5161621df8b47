"""Exact ray casting of a synthetic scene: depth, shaded colour and normals per pixel.

Rendering intersects every ray with every primitive in closed form and keeps the
nearest hit, so depth is exact up to float64 rounding; there is no rasteriser. Colour
is albedo times a shading term that depends only on the surface normal
(:func:`eslam.synthetic.materials.shading`), so it is the same from every viewpoint.

Ray directions come from :mod:`eslam.geometry.camera` with unit z in the camera frame,
so the ray parameter t of a hit IS its depth along the optical axis.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import torch

from eslam.geometry.camera import camera_to_world_rays, pixel_grid, pixels_to_camera_directions
from eslam.synthetic.materials import shading
from eslam.synthetic.primitives import Scene
from eslam.types import Intrinsics


@dataclass(frozen=True, eq=False)
class RenderedView:
    """Everything a render computes per pixel.

    Attributes:
        rgb: (H, W, 3) uint8.  depth: (H, W) float32 m along the optical axis, 0 = miss.
        normals: (H, W, 3) float64 world-frame unit normals.
        primitive: (H, W) int64 index into scene.primitives, -1 = miss.
        cos_incidence: (H, W) float64 |cos| of the angle between ray and normal.
    """

    rgb: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    primitive: np.ndarray
    cos_incidence: np.ndarray


def cast_rays(
    scene: Scene, origin: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of rays ``origin + t * directions`` (N, 3) over all primitives.

    Rays that miss an object's bounding sphere skip its exact test (a speed-up only:
    the cull is conservative, so the result is that of testing every ray).

    Returns:
        t (N,) float64 (inf = miss) and primitive*8 + part (N,) int64 (-1 = miss).
    """
    best = np.full(len(directions), np.inf)
    label = np.full(len(directions), -1, dtype=np.int64)
    lengths = np.linalg.norm(directions, axis=1)
    for index, primitive in enumerate(scene.primitives):
        rays = slice(None)
        bound = getattr(primitive, "bounding_sphere", None)
        if bound is not None:
            offset = bound[0] - origin
            reach = bound[1] * (1.0 + 1e-9) + 1e-9
            if offset @ offset > reach**2:
                along = (directions @ offset) / lengths
                rays = np.flatnonzero((along > 0) & (offset @ offset - along**2 <= reach**2))
        t, part = primitive.intersect(origin, directions[rays])
        closer = t < best[rays]
        if isinstance(rays, np.ndarray):
            rays = rays[closer]
        else:
            rays = np.flatnonzero(closer)
        best[rays] = t[closer]
        label[rays] = index * 8 + part[closer]
    return best, label


@functools.lru_cache(maxsize=8)
def _camera_directions(intrinsics: Intrinsics) -> torch.Tensor:
    uv = pixel_grid(intrinsics, dtype=torch.float64)
    return pixels_to_camera_directions(uv, intrinsics).reshape(-1, 3)


def render_view(scene: Scene, intrinsics: Intrinsics, c2w: np.ndarray) -> RenderedView:
    """Ray cast one view exactly: depth along the optical axis, shaded colour, normals."""
    origins, directions = camera_to_world_rays(
        _camera_directions(intrinsics), torch.as_tensor(c2w, dtype=torch.float64)
    )
    origin, directions = origins[0].numpy(), directions.numpy()
    t, label = cast_rays(scene, origin, directions)
    colour = np.zeros_like(directions)
    normals = np.zeros_like(directions)
    owner = np.where(label >= 0, label // 8, -1)
    for index, primitive in enumerate(scene.primitives):
        mask = np.flatnonzero(owner == index)
        points = origin + t[mask, None] * directions[mask]
        parts = label[mask] % 8
        normals[mask] = primitive.normals(points, parts)
        colour[mask] = primitive.albedo(points, parts) * shading(normals[mask])[:, None]
    hit = label >= 0
    cosine = np.abs(np.einsum("ni,ni->n", normals, directions)) / np.linalg.norm(directions, axis=1)
    h, w = intrinsics.height, intrinsics.width
    return RenderedView(
        rgb=np.clip(colour * 255.0 + 0.5, 0, 255).astype(np.uint8).reshape(h, w, 3),
        depth=np.where(hit, t, 0.0).astype(np.float32).reshape(h, w),
        normals=normals.reshape(h, w, 3),
        primitive=owner.reshape(h, w),
        cos_incidence=cosine.reshape(h, w),
    )


def render_frame(
    scene: Scene, intrinsics: Intrinsics, c2w: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Render ``scene`` from camera-to-world ``c2w`` (4, 4), OpenCV axes.

    Returns:
        rgb (H, W, 3) uint8 and depth (H, W) float32 metres along the optical axis
        (exact up to float32 rounding; 0 where a ray hits nothing).
    """
    view = render_view(scene, intrinsics, c2w)
    return view.rgb, view.depth
