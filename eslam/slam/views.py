"""Images on the compute device, ready for ray sampling: one type for tracking and mapping.

A View has the same shapes for every frame of a camera (P = H * W pixels), and drawing
rays from it never synchronises with the host: the sampleable pixels are kept as a
running count (a cumulative sum over a mask) instead of a variable-length index list,
so the optimisation steps that draw from it can be captured or compiled.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from eslam.render.rays import rays_from_pixels
from eslam.types import RayBatch


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
    cumulative = torch.cumsum(valid.reshape(-1).to(torch.int64), dim=0)
    return View(
        rgb=rgb.reshape(-1, 3),
        depth=torch.nan_to_num(depth, nan=0.0).reshape(-1),
        directions=directions,
        cumulative=cumulative,
        count=cumulative[-1],
    )


def sample_view_pixels(view: View, count: int, generator: torch.Generator) -> torch.Tensor:
    """(count,) int64 pixel indices drawn uniformly, with replacement, among the sampleable.

    The k-th sampleable pixel (0-based) is the first p with cumulative[p] >= k + 1, and
    k = floor(u * M) with u ~ U[0, 1) and M = ``view.count``: fixed shapes, no host sync.
    A view without sampleable pixels yields pixel 0 (callers check
    :meth:`View.sampleable_pixels` once per frame).
    """
    uniform = torch.rand(count, generator=generator, device=view.cumulative.device)
    rank = (uniform * view.count).to(torch.int64)
    rank = torch.minimum(rank, (view.count - 1).clamp(min=0))
    pixels = torch.searchsorted(view.cumulative, rank + 1)
    return pixels.clamp(max=view.cumulative.shape[0] - 1)


def sample_view_rays(
    view: View, c2w: torch.Tensor, count: int, generator: torch.Generator
) -> RayBatch:
    """``count`` rays through pixels drawn uniformly (with replacement) from the sampleable.

    Differentiable with respect to ``c2w`` (4, 4), so poses can be optimised.
    """
    pixels = sample_view_pixels(view, count, generator)
    return rays_from_pixels(view.directions[pixels], c2w, view.depth[pixels], view.rgb[pixels])


def concatenate_rays(batches: list[RayBatch]) -> RayBatch:
    """One RayBatch holding the rays of several batches, in order."""
    return RayBatch(
        origins=torch.cat([b.origins for b in batches]),
        directions=torch.cat([b.directions for b in batches]),
        depth=torch.cat([b.depth for b in batches]),
        rgb=torch.cat([b.rgb for b in batches]),
    )
