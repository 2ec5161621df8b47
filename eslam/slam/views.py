"""Images on the compute device, ready for ray sampling: one type for tracking and mapping.

A View has the same shapes for every frame of a camera (P = H * W pixels), and drawing
rays from it never synchronises with the host: the sampleable pixels are kept as a
running count (a cumulative sum over a mask) instead of a variable-length index list,
so the optimisation steps that draw from it can be captured or compiled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from eslam.config import RenderConfig
from eslam.render.rays import rays_from_pixels
from eslam.render.renderer import SceneFieldLike, render_rays
from eslam.render.sampling import draw_depth_guided_noise
from eslam.types import RayBatch, RenderOutput


@dataclass(frozen=True, eq=False)
class View:
    """One RGB-D image flattened for sampling (P = H * W pixels).

    Attributes:
        rgb: (P, 3) float32 colour in [0, 1].
        depth: (P,) float32 depth in metres, 0 = invalid.
        directions: (P, 3) camera-frame ray directions with unit z.
        cumulative: (P,) int64 running count of sampleable pixels (valid depth, outside
            the ignored border): ``cumulative[p]`` = sampleable pixels among 0..p.
        count: 0-d int64 tensor, the number of sampleable pixels (``cumulative[-1]``).
    """

    rgb: torch.Tensor
    depth: torch.Tensor
    directions: torch.Tensor
    cumulative: torch.Tensor
    count: torch.Tensor

    def sampleable_pixels(self) -> int:
        """Number of pixels rays may be drawn from (reads the device: call between steps)."""
        return int(self.count)


def upload_frame(
    rgb: np.ndarray, depth: np.ndarray, device: torch.device | str
) -> tuple[torch.Tensor, torch.Tensor]:
    """A frame's images on the compute device: (H, W, 3) uint8 -> float32 colour in [0, 1]
    (converted on the device, so only bytes travel) and (H, W) float32 depth in metres.
    A read-only array (a reader's cache, a resized view) is copied first: torch shares
    memory with the array and does not take read-only ones without a warning."""
    colour = torch.from_numpy(writable(rgb)).to(device).float() / 255.0
    return colour, torch.from_numpy(writable(depth)).to(device)


def writable(array: np.ndarray) -> np.ndarray:
    """``array``, or a copy of it when it is read-only."""
    return array if array.flags.writeable else array.copy()


def make_view(
    rgb: torch.Tensor, depth: torch.Tensor, directions: torch.Tensor, border: int = 0
) -> View:
    """Build a View from (H, W, 3) colour in [0, 1] and (H, W) depth in metres.

    Args:
        directions: (H * W, 3) from :func:`eslam.render.rays.camera_directions` (once per
            camera).
        border: pixels at each image edge that are never sampled.
    """
    height, width = depth.shape
    valid = torch.isfinite(depth) & (depth > 0)
    if border > 0:
        inside = torch.zeros_like(valid)
        inside[border : height - border, border : width - border] = True
        valid &= inside
    return _counted_view(
        rgb.reshape(-1, 3), torch.nan_to_num(depth, nan=0.0).reshape(-1), directions, valid
    )


def _counted_view(
    rgb: torch.Tensor, depth: torch.Tensor, directions: torch.Tensor, sampleable: torch.Tensor
) -> View:
    """A View of (P, 3) colour, (P,) depth and (P, 3) directions whose rays are drawn
    from the pixels where ``sampleable`` (any shape with P elements) is true."""
    cumulative = torch.cumsum(sampleable.reshape(-1).to(torch.int64), dim=0)
    return View(rgb, depth, directions, cumulative=cumulative, count=cumulative[-1])


def sampleable_mask(view: View) -> torch.Tensor:
    """(P,) bool: the pixels rays may be drawn from (where ``view.cumulative`` steps)."""
    previous = torch.cat((view.cumulative.new_zeros(1), view.cumulative[:-1]))
    return view.cumulative > previous


def restrict_view(view: View, keep: torch.Tensor) -> View:
    """``view`` with only its sampleable pixels where ``keep`` (P,) is true left
    sampleable (same images)."""
    return _counted_view(view.rgb, view.depth, view.directions, sampleable_mask(view) & keep)


def pixels_from_uniforms(view: View, uniform: torch.Tensor) -> torch.Tensor:
    """(n,) int64 pixels of ``view`` chosen by (n,) uniforms in [0, 1): uniform, with
    replacement, among the sampleable pixels.

    The k-th sampleable pixel (0-based) is the first p with cumulative[p] >= k + 1, and
    k = floor(u * M) with M = ``view.count``: fixed shapes, no host sync. A view without
    sampleable pixels yields pixel 0 (callers check :meth:`View.sampleable_pixels` once
    per frame).
    """
    rank = (uniform * view.count).to(torch.int64)
    rank = torch.minimum(rank, (view.count - 1).clamp(min=0))
    pixels = torch.searchsorted(view.cumulative, rank + 1)
    return pixels.clamp(max=view.cumulative.shape[0] - 1)


def sample_view_pixels(view: View, count: int, generator: torch.Generator) -> torch.Tensor:
    """(count,) pixels drawn uniformly, with replacement, among the sampleable ones."""
    uniform = torch.rand(count, generator=generator, device=view.cumulative.device)
    return pixels_from_uniforms(view, uniform)


def view_rays(view: View, c2w: torch.Tensor, pixels: torch.Tensor) -> RayBatch:
    """The rays through ``pixels`` (n,) of ``view`` seen from ``c2w`` (4, 4), differentiable
    with respect to ``c2w``."""
    return rays_from_pixels(view.directions[pixels], c2w, view.depth[pixels], view.rgb[pixels])


def sample_view_rays(
    view: View, c2w: torch.Tensor, count: int, generator: torch.Generator
) -> RayBatch:
    """``count`` rays through pixels drawn uniformly (with replacement) from the sampleable.

    Differentiable with respect to ``c2w`` (4, 4), so poses can be optimised.
    """
    return view_rays(view, c2w, sample_view_pixels(view, count, generator))


@dataclass(frozen=True, eq=False)
class RayDraws:
    """Every random number one optimisation step uses, drawn before it runs.

    Drawing them ahead (in the order the step used to draw them itself) leaves the
    step's computation a pure function of tensors, which ``torch.compile`` traces as
    one graph and a CUDA graph can replay.

    Attributes:
        pixels: (V, n) uniforms choosing n pixels in each of V views.
        jitter: the stratified (V n, S1) and surface (V n, S2) sample jitter, or None
            when samples are not perturbed.
    """

    pixels: torch.Tensor
    jitter: tuple[torch.Tensor, torch.Tensor] | None


def draw_rays(
    views: int,
    per_view: int,
    render: RenderConfig,
    generator: torch.Generator,
    device: torch.device,
) -> RayDraws:
    """The draws of one step over ``views`` views with ``per_view`` rays each: the pixels
    of each view in turn, then the jitter of all rays (the renderer's order)."""
    pixels = torch.stack(
        [torch.rand(per_view, generator=generator, device=device) for _ in range(views)]
    )
    jitter = None
    if render.perturb:
        like = pixels
        jitter = draw_depth_guided_noise(
            views * per_view, render.samples_stratified, render.samples_surface, generator, like
        )
    return RayDraws(pixels=pixels, jitter=jitter)


def concatenate_rays(batches: list[RayBatch]) -> RayBatch:
    """One RayBatch holding the rays of several batches, in order."""
    return RayBatch(
        origins=torch.cat([b.origins for b in batches]),
        directions=torch.cat([b.directions for b in batches]),
        depth=torch.cat([b.depth for b in batches]),
        rgb=torch.cat([b.rgb for b in batches]),
    )


def render_drawn(
    field: SceneFieldLike, rays: RayBatch, draws: RayDraws, render: RenderConfig
) -> RenderOutput:
    """Render training rays (all with depth) with the jitter ``draws`` holds: no checks,
    no random state, no host sync (the optimisation steps' renderer call)."""
    return render_rays(field, rays, render, perturb=render.perturb, check=False, noise=draws.jitter)
