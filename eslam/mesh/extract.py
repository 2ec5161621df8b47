"""Mesh extraction: marching cubes of the learned TSDF on a regular grid (method.md section 6).

The TSDF is evaluated on a grid of step ``resolution`` inside the field's bound, in
chunks (memory stays bounded), and marching cubes (scikit-image) runs only on grid
points that some keyframe observed: a point is observed when it projects inside a
keyframe's image, in front of the camera, no farther than the measured depth there plus
the truncation. Unobserved space therefore produces no phantom surfaces. Vertex colours
come from the appearance decoder.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from eslam.data.mesh_io import TriangleMesh
from eslam.field.scene_field import SceneField
from eslam.geometry.camera import project_points
from eslam.types import Intrinsics


@dataclass(frozen=True, eq=False)
class ObservedViews:
    """The keyframes that define observed space.

    Attributes:
        poses: (K, 4, 4) camera-to-world poses.
        depths: (K, H, W) measured depth, metres, 0 = invalid.
        intrinsics: their camera.
        margin: how far behind the measured depth still counts as observed, metres.
    """

    poses: torch.Tensor
    depths: torch.Tensor
    intrinsics: Intrinsics
    margin: float


def observed_mask(points: torch.Tensor, views: ObservedViews) -> torch.Tensor:
    """(M,) bool: whether any view observed each of the (M, 3) world points."""
    seen = torch.zeros(points.shape[0], dtype=torch.bool, device=points.device)
    k = views.intrinsics
    for pose, depth in zip(views.poses, views.depths, strict=True):
        uv, z = project_points(points, k, pose.to(points))
        u, v = uv[:, 0].round().long(), uv[:, 1].round().long()
        inside = (z > 0) & (u >= 0) & (u < k.width) & (v >= 0) & (v < k.height)
        measured = torch.zeros_like(z)
        measured[inside] = depth.to(points)[v[inside], u[inside]]
        seen |= inside & (measured > 0) & (z <= measured + views.margin)
    return seen


@torch.no_grad()
def extract_mesh(
    field: SceneField,
    resolution: float,
    views: ObservedViews | None = None,
    chunk: int = 262144,
) -> TriangleMesh:
    """Marching cubes of ``field``'s TSDF at level 0 on a grid of step ``resolution`` metres.

    Args:
        views: observed space; None meshes the whole bound (phantom surfaces possible).
        chunk: points evaluated per field query (bounds memory).

    Returns:
        The mesh in world coordinates with vertex colours; empty when no surface is found.
    """
    from skimage.measure import marching_cubes

    bound = field.bound.detach().cpu().double()
    axes = [
        torch.arange(float(lo), float(hi) + 0.5 * resolution, resolution, dtype=torch.float64)
        for lo, hi in bound
    ]
    shape = tuple(len(a) for a in axes)
    device = field.bound.device
    sdf = np.ones(shape, dtype=np.float32)
    mask = np.zeros(shape, dtype=bool)
    plane = shape[1] * shape[2]
    slab = max(1, chunk // plane)
    grid_yz = torch.stack(torch.meshgrid(axes[1], axes[2], indexing="ij"), dim=-1).reshape(-1, 2)
    for start in range(0, shape[0], slab):
        xs = axes[0][start : start + slab]
        points = torch.cat(
            (xs.repeat_interleave(len(grid_yz)).unsqueeze(1), grid_yz.repeat(len(xs), 1)), dim=1
        ).to(device=device, dtype=torch.float32)
        values = field.query(points, with_rgb=False).sdf
        sdf[start : start + len(xs)] = values.reshape(len(xs), *shape[1:]).cpu().numpy()
        if views is not None:
            seen = observed_mask(points, views)
            mask[start : start + len(xs)] = seen.reshape(len(xs), *shape[1:]).cpu().numpy()
    if views is None:
        mask[:] = True
    if not (mask.any() and sdf[mask].min() < 0 < sdf[mask].max()):
        return _empty_mesh()
    vertices, faces, _, _ = marching_cubes(
        sdf, level=0.0, spacing=(resolution,) * 3, mask=mask, allow_degenerate=False
    )
    vertices = vertices + bound[:, 0].numpy()
    colours = np.zeros((len(vertices), 3), dtype=np.uint8)
    for start in range(0, len(vertices), chunk):
        points = torch.from_numpy(vertices[start : start + chunk]).to(device, torch.float32)
        rgb = field.query(points, with_rgb=True).rgb
        colours[start : start + chunk] = (rgb.clamp(0, 1) * 255).round().byte().cpu().numpy()
    return TriangleMesh(
        vertices=vertices.astype(np.float64), faces=faces.astype(np.int64), colours=colours
    )


def _empty_mesh() -> TriangleMesh:
    return TriangleMesh(
        vertices=np.zeros((0, 3)),
        faces=np.zeros((0, 3), dtype=np.int64),
        colours=np.zeros((0, 3), dtype=np.uint8),
    )
