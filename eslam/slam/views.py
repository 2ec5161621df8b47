"""Images on the compute device, ready for ray sampling: one type for tracking and mapping."""

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
        candidates: (M,) int64 indices of pixels that may be sampled (valid depth,
            outside the ignored border).
    """

    rgb: torch.Tensor
    depth: torch.Tensor
    directions: torch.Tensor
    candidates: torch.Tensor


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
    candidates = torch.nonzero(valid.reshape(-1)).squeeze(1)
    return View(
        rgb=rgb.reshape(-1, 3),
        depth=torch.nan_to_num(depth, nan=0.0).reshape(-1),
        directions=directions,
        candidates=candidates,
    )


def sample_view_rays(
    view: View, c2w: torch.Tensor, count: int, generator: torch.Generator
) -> RayBatch:
    """``count`` rays through pixels drawn uniformly (with replacement) from the candidates.

    Differentiable with respect to ``c2w`` (4, 4), so poses can be optimised.
    """
    pick = torch.randint(
        len(view.candidates), (count,), generator=generator, device=view.candidates.device
    )
    pixels = view.candidates[pick]
    return rays_from_pixels(view.directions[pixels], c2w, view.depth[pixels], view.rgb[pixels])


def concatenate_rays(batches: list[RayBatch]) -> RayBatch:
    """One RayBatch holding the rays of several batches, in order."""
    return RayBatch(
        origins=torch.cat([b.origins for b in batches]),
        directions=torch.cat([b.directions for b in batches]),
        depth=torch.cat([b.depth for b in batches]),
        rgb=torch.cat([b.rgb for b in batches]),
    )
