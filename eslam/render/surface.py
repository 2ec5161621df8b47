"""Novel views of a map: colour by volume rendering, depth of the surface itself.

A view rendered without measured depth (``eslam render``, the live viewer's rendered
frames) takes the paper's samples for rays without depth (docs/method.md section 2:
uniform samples from the camera to the exit of the bound box, then importance samples
from the coarse weights; :func:`~eslam.render.renderer.render_rays_without_depth`).
Its colour is the volume-rendered colour sum_i w_i c_i. Its depth is NOT the
volume-rendered depth sum_i w_i z_i: ESLAM's density is not zero in free space nor
symmetric about the surface, so that depth comes out short by centimetres (the more
samples a ray takes, the shorter; see :mod:`eslam.render.held_out`). The depth written
is where the TSDF first crosses zero among those same samples, refined by bisection:
the surface a mesh of the map shows.
"""

from __future__ import annotations

import torch

from eslam.config import RenderConfig
from eslam.render.rays import camera_directions
from eslam.render.renderer import DEFAULT_CHUNK, SceneFieldLike, render_rays_without_depth
from eslam.types import Intrinsics

BISECTION_STEPS = 8
"""Halvings of the bracket around a zero crossing: a bracket of 8 cm (64 samples over
5 m) shrinks to 0.3 mm before the final linear interpolation."""


def first_zero_crossing(z: torch.Tensor, sdf: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Index of the first sample pair going from s > 0 to s <= 0 along each ray.

    Args:
        z: (N, S) sorted sample depths.
        sdf: (N, S) TSDF at those samples.

    Returns:
        index (N,) long: the crossing lies in [z_index, z_index+1] (0 where none), and
        hit (N,) bool: whether the ray has a crossing.

    Example:
        s = [0.5, 0.2, -0.3, 0.4, -0.1] -> index 1, hit True.
    """
    crossing = (sdf[:, :-1] > 0) & (sdf[:, 1:] <= 0)
    hit = crossing.any(dim=1)
    index = crossing.to(torch.uint8).argmax(dim=1)
    return index, hit


def interpolate_zero(
    z_a: torch.Tensor, z_b: torch.Tensor, s_a: torch.Tensor, s_b: torch.Tensor
) -> torch.Tensor:
    """Where the straight line through (z_a, s_a) and (z_b, s_b) crosses zero.

    z = z_a + (z_b - z_a) s_a / (s_a - s_b), for s_a > 0 >= s_b (the TSDF is linear in z
    near a surface, within the truncation band).
    """
    return z_a + (z_b - z_a) * s_a / (s_a - s_b).clamp_min(1e-12)


@torch.no_grad()
def refine_zero_crossing(
    field: SceneFieldLike,
    origins: torch.Tensor,
    directions: torch.Tensor,
    z_a: torch.Tensor,
    z_b: torch.Tensor,
    steps: int = BISECTION_STEPS,
) -> torch.Tensor:
    """Depth of the TSDF's zero in each bracket [z_a, z_b] (s(z_a) > 0 >= s(z_b)).

    ``steps`` bisections (each keeps the half whose ends differ in sign), then
    :func:`interpolate_zero` on the last bracket. The TSDF is clamped to [-1, 1] beyond
    the truncation band, so a straight line through a coarse bracket's ends would be
    wrong by up to a bracket's width; bisection first shrinks the bracket into the
    band (root bracketing by bisection, e.g. Press et al., Numerical Recipes, 9.1).

    Args:
        origins, directions: (N, 3) rays (directions with unit camera z).
        z_a, z_b: (N,) the bracket's ends.

    Returns:
        (N,) depths in [z_a, z_b].
    """

    def tsdf(z: torch.Tensor) -> torch.Tensor:
        return field.query(origins + z[:, None] * directions, with_rgb=False).sdf

    s_a, s_b = tsdf(z_a), tsdf(z_b)
    for _ in range(steps):
        middle = 0.5 * (z_a + z_b)
        s_m = tsdf(middle)
        front = s_m > 0
        z_a = torch.where(front, middle, z_a)
        s_a = torch.where(front, s_m, s_a)
        z_b = torch.where(front, z_b, middle)
        s_b = torch.where(front, s_b, s_m)
    return interpolate_zero(z_a, z_b, s_a, s_b)


@torch.no_grad()
def render_novel_rays(
    field: SceneFieldLike,
    origins: torch.Tensor,
    directions: torch.Tensor,
    config: RenderConfig,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Surface depth and colour of rays without measured depth (module doc).

    Returns:
        depth (N,) metres along the optical axis, 0 where the ray meets no surface in
        the bound box, and rgb (N, 3) in [0, 1] (volume-rendered; 0 where no surface).
    """
    output = render_rays_without_depth(field, origins, directions, config)
    index, hit = first_zero_crossing(output.z_vals, output.sdf)
    pick = index[:, None]
    z_a = output.z_vals.gather(1, pick)[:, 0]
    z_b = output.z_vals.gather(1, pick + 1)[:, 0]
    depth = torch.zeros_like(z_a)
    rgb = torch.zeros(len(z_a), 3, dtype=z_a.dtype, device=z_a.device)
    if bool(hit.any()):
        rows = torch.nonzero(hit).squeeze(1)
        depth[rows] = refine_zero_crossing(
            field, origins[rows], directions[rows], z_a[rows], z_b[rows]
        )
        if output.rgb is not None:
            rgb[rows] = output.rgb[rows]
    return depth, rgb


@torch.no_grad()
def render_novel_view(
    field: SceneFieldLike,
    intrinsics: Intrinsics,
    c2w: torch.Tensor,
    config: RenderConfig,
    chunk: int = DEFAULT_CHUNK,
) -> tuple[torch.Tensor, torch.Tensor]:
    """A whole camera rendered from the map alone (module doc), ``chunk`` rays at a time.

    Args:
        c2w: (4, 4) camera-to-world pose (OpenCV axes), on the field's device.

    Returns:
        depth (H, W) metres (0 = no surface) and rgb (H, W, 3) in [0, 1].
    """
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    c2w = c2w.to(dtype=field.beta.dtype)
    directions = camera_directions(intrinsics, device=c2w.device, dtype=c2w.dtype)
    directions = directions @ c2w[:3, :3].T
    origins = c2w[:3, 3].expand_as(directions)
    depths, colours = [], []
    for start in range(0, len(directions), chunk):
        part = slice(start, start + chunk)
        depth, rgb = render_novel_rays(field, origins[part], directions[part], config)
        depths.append(depth)
        colours.append(rgb)
    height, width = intrinsics.height, intrinsics.width
    return torch.cat(depths).reshape(height, width), torch.cat(colours).reshape(height, width, 3)
