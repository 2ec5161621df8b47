"""The one renderer tracking and mapping share: rays in, depth and colour out.

docs/method.md section 2.

``render_rays`` renders rays with a measured depth (ESLAM's training rays);
``render_rays_without_depth`` renders novel views (uniform samples to the scene box's
exit, then importance samples); ``render_image`` renders a whole camera in chunks
without gradients, for visualisation.
"""

from __future__ import annotations

from typing import Protocol

import torch

from eslam.config import RenderConfig
from eslam.render.rays import camera_directions, rays_from_pixels
from eslam.render.sampling import (
    depth_guided_samples,
    importance_samples,
    midpoint_edges,
    ray_box_intersection,
    uniform_samples,
)
from eslam.render.volume import bell_weights, composite, sdf_to_weights
from eslam.stages import stage
from eslam.types import FieldOutput, Intrinsics, RayBatch, RenderOutput


class SceneFieldLike(Protocol):
    """What the renderer needs from a scene field.

    Attributes:
        beta: scalar tensor, the learnable sharpness of the SDF-to-density map.
        truncation: T, metres.
        bound: (3, 2) scene box [[xmin, xmax], [ymin, ymax], [zmin, zmax]], metres.
    """

    beta: torch.Tensor
    truncation: float
    bound: torch.Tensor

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput:
        """Field at (N, 3) world points: TSDF (N,) in units of T, colour (N, 3) or None."""
        ...


def weights_from_sdf(sdf: torch.Tensor, beta: torch.Tensor, config: RenderConfig) -> torch.Tensor:
    """(N, S) rendering weights from (N, S) TSDF per ``config.density``."""
    if config.density == "bell":
        return bell_weights(sdf, beta)
    return sdf_to_weights(sdf, beta)


def _shade(
    field: SceneFieldLike,
    origins: torch.Tensor,
    directions: torch.Tensor,
    z: torch.Tensor,
    colour: bool,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Query the field once at all N * S points o + z d: TSDF (N, S), colour (N, S, 3) or None."""
    count, samples = z.shape
    points = origins[:, None, :] + z[..., None] * directions[:, None, :]
    out = field.query(points.reshape(-1, 3), with_rgb=colour)
    sdf = out.sdf.reshape(count, samples)
    rgb = out.rgb.reshape(count, samples, 3) if colour and out.rgb is not None else None
    return sdf, rgb


def _integrate(
    field: SceneFieldLike,
    origins: torch.Tensor,
    directions: torch.Tensor,
    z: torch.Tensor,
    config: RenderConfig,
) -> RenderOutput:
    sdf, rgb = _shade(field, origins, directions, z, config.render_colour)
    with stage("rendering"):
        weights = weights_from_sdf(sdf, field.beta, config)
        depth = composite(weights, z)
        colour = composite(weights, rgb) if rgb is not None else None
    return RenderOutput(depth=depth, rgb=colour, z_vals=z, sdf=sdf, weights=weights)


def render_rays(
    field: SceneFieldLike,
    rays: RayBatch,
    config: RenderConfig,
    perturb: bool,
    generator: torch.Generator | None = None,
    *,
    check: bool = True,
    noise: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> RenderOutput:
    """Render rays with a measured depth D: ESLAM's depth-guided sampling and compositing.

    z = depth_guided_samples(D) ((N, S), S = samples_stratified + samples_surface),
    points o + z d queried ONCE, weights from the TSDF (``config.density``),
    depth = sum_i w_i z_i, rgb = sum_i w_i c_i (None when ``config.render_colour`` is off).
    Differentiable w.r.t. the field and the rays (hence the poses).

    Args:
        rays: N rays; every ``rays.depth`` must be finite and > 0.
        perturb: jitter the samples within their bins (True while optimising).
        generator: randomness of the jitter.
        check: verify that every ray has a depth (a host sync). The optimisation steps
            pass False: they draw rays only through pixels with depth, and must not sync.
        noise: the jitter drawn ahead (:func:`~eslam.render.sampling.draw_depth_guided_noise`)
            instead of drawing it from ``generator`` here.

    Raises:
        ValueError: when ``check`` and a ray has no valid depth.
    """
    if check and not bool(torch.isfinite(rays.depth).all() & (rays.depth > 0).all()):
        raise ValueError(
            "render_rays needs a finite depth > 0 on every ray; "
            "use render_rays_without_depth for rays without depth"
        )
    with stage("ray sampling"):
        z = depth_guided_samples(
            rays.depth.detach(),
            config.samples_stratified,
            config.samples_surface,
            field.truncation,
            surface_band=config.surface_band,
            far_factor=config.far_factor,
            perturb=perturb,
            generator=generator,
            noise=noise,
        )
    return _integrate(field, rays.origins, rays.directions, z, config)


def importance_bins(
    z: torch.Tensor, weights: torch.Tensor, config: RenderConfig
) -> tuple[torch.Tensor, torch.Tensor]:
    """Bin edges and weights for hierarchical sampling from coarse samples z, weights (N, S).

    ESLAM's alpha is the opacity of a sample (sigmoid(-beta s) switches on once s < 0),
    so a large w_i says the surface lies in (z_{i-1}, z_i]: bins [z_{i-1}, z_i] carry
    w_i (edges z, weights w_1..w_{S-1}). The bell weight peaks AT the crossing, so each
    sample owns the interval between its neighbours' midpoints.

    Returns:
        edges (N, B + 1) and weights (N, B).
    """
    if config.density == "bell":
        return midpoint_edges(z), weights
    return z, weights[:, 1:]


def render_rays_without_depth(
    field: SceneFieldLike,
    origins: torch.Tensor,
    directions: torch.Tensor,
    config: RenderConfig,
    *,
    n_importance: int | None = None,
    perturb: bool = False,
    generator: torch.Generator | None = None,
) -> RenderOutput:
    """Render rays with no measured depth (novel views), hierarchical sampling (release).

    1. ``config.samples_no_depth`` uniform samples from max(entry, 0) to the exit of the
       field's bound box; 2. coarse weights from a first query (no gradient);
    3. ``n_importance`` (default ``config.samples_surface``; 0 skips it) samples from
       those weights by inverse cdf (:func:`importance_bins`); 4. merged, sorted, one
       final query (importance sampling needs samples_no_depth >= 2). Rays that miss the
       box get zero weights (depth 0, colour 0).

    Args:
        origins: (N, 3) world ray origins.
        directions: (N, 3) world directions with unit camera z.

    Returns:
        RenderOutput with S = samples_no_depth + n_importance samples per ray.
    """
    n_importance = config.samples_surface if n_importance is None else n_importance
    near, far = ray_box_intersection(origins.detach(), directions.detach(), field.bound)
    hit = far > near
    near = torch.where(hit, near, 0.0)
    far = torch.where(hit, far, 0.0)
    z = uniform_samples(near, far, config.samples_no_depth, perturb, generator)
    if n_importance > 0 and config.samples_no_depth > 1:
        with torch.no_grad():
            sdf, _ = _shade(field, origins, directions, z, colour=False)
            edges, weights = importance_bins(z, weights_from_sdf(sdf, field.beta, config), config)
            fine = importance_samples(edges, weights, n_importance, perturb, generator)
        z = torch.sort(torch.cat((z, fine), dim=1), dim=1).values
    output = _integrate(field, origins, directions, z, config)
    if bool(hit.all()):
        return output
    keep = hit.to(output.weights.dtype)
    return RenderOutput(
        depth=output.depth * keep,
        rgb=output.rgb * keep[:, None] if output.rgb is not None else None,
        z_vals=z,
        sdf=output.sdf,
        weights=output.weights * keep[:, None],
    )


DEFAULT_CHUNK = 4096
"""Rays rendered at once by ``render_image``: bounds memory to about chunk * S points."""


@torch.no_grad()
def render_image(
    field: SceneFieldLike,
    intrinsics: Intrinsics,
    c2w: torch.Tensor,
    config: RenderConfig,
    depth: torch.Tensor | None = None,
    chunk: int = DEFAULT_CHUNK,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Render a whole image (no gradients, deterministic samples, ``chunk`` rays at a time).

    Pixels with a measured depth (``depth`` given, > 0) use the depth-guided samples
    ESLAM visualises with (:func:`render_rays`); the other pixels, or all of them when
    ``depth`` is None, use :func:`render_rays_without_depth`.

    Args:
        c2w: (4, 4) camera-to-world pose (OpenCV axes).
        depth: optional (H, W) measured depth, metres, 0 = none.
        chunk: rays per field query batch.

    Returns:
        depth (H, W) metres and rgb (H, W, 3) in [0, 1] (None when
        ``config.render_colour`` is off), on the device of ``c2w``.
    """
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    height, width = intrinsics.height, intrinsics.width
    dirs_cam = camera_directions(intrinsics, device=c2w.device, dtype=c2w.dtype)
    count = dirs_cam.shape[0]
    measured = torch.zeros(count, device=c2w.device, dtype=c2w.dtype)
    if depth is not None:
        if depth.shape != (height, width):
            raise ValueError(f"depth must be ({height}, {width}), got {tuple(depth.shape)}")
        measured = torch.nan_to_num(depth.to(measured), nan=0.0).reshape(-1)
    rays = rays_from_pixels(dirs_cam, c2w, measured, torch.zeros_like(dirs_cam))
    out_depth = torch.zeros(count, device=c2w.device, dtype=c2w.dtype)
    out_rgb = torch.zeros(count, 3, device=c2w.device, dtype=c2w.dtype)
    for start in range(0, count, chunk):
        part = slice(start, start + chunk)
        origins, directions, d = rays.origins[part], rays.directions[part], measured[part]
        with_depth = torch.isfinite(d) & (d > 0)
        for select, guided in ((with_depth, True), (~with_depth, False)):
            index = torch.nonzero(select).squeeze(1)
            if index.numel() == 0:
                continue
            if guided:
                colour = torch.zeros_like(origins[index])
                sub = RayBatch(origins[index], directions[index], d[index], colour)
                output = render_rays(field, sub, config, perturb=False)
            else:
                output = render_rays_without_depth(field, origins[index], directions[index], config)
            out_depth[start + index] = output.depth
            if output.rgb is not None:
                out_rgb[start + index] = output.rgb
    rgb = out_rgb.reshape(height, width, 3) if config.render_colour else None
    return out_depth.reshape(height, width), rgb
