"""Tracking on observed space only (``tracking.observed_only``; docs/tracking.md).

The map holds measurements only where some keyframe looked: in front of each keyframe's
depth and up to the truncation T behind it (:mod:`eslam.mesh.observed`). Elsewhere the
field still answers, from feature planes shared along an axis and trained on other
surfaces: an extrapolation, not a measurement. A tracked frame's points can fall there
(the strip of the image that has come into view since the last keyframe, surfaces an
occluder hid); with the option on, such pixels are taken out of the frame's
:class:`~eslam.slam.views.View` before tracking. (What it changed on real data:
docs/results.md, "What we tried and ruled out".)

Observed space is tested at the motion model's guess, on a grid of every ``stride``-th
pixel in both directions; each pixel takes its grid point's answer. A grid point with
no depth gives its block the benefit of the doubt (kept where the pixel itself has
depth): the test is a filter of what the map cannot know, not a second validity mask.
"""

from __future__ import annotations

import torch

from eslam.mesh.observed import ObservedViews, observed_mask
from eslam.slam.views import View

STRIDE = 4
"""Pixels between the grid points at which observed space is tested (both directions)."""


def observed_pixels(
    view: View, pose: torch.Tensor, views: ObservedViews, stride: int = STRIDE
) -> torch.Tensor:
    """(P,) bool: pixels of ``view`` whose depth point, seen from ``pose`` (4, 4
    camera-to-world), lies in space a view of ``views`` observed (module doc: tested
    on a grid of every ``stride``-th pixel; no depth at a grid point counts as observed).
    The newest views are tested first (they see most of the frame)."""
    height, width = views.intrinsics.height, views.intrinsics.width
    rows = torch.arange(0, height, stride, device=view.depth.device)
    cols = torch.arange(0, width, stride, device=view.depth.device)
    grid = (rows[:, None] * width + cols[None, :]).reshape(-1)
    depth = view.depth[grid]
    camera = view.directions[grid] * depth[:, None]
    pose = pose.to(camera)
    world = camera @ pose[:3, :3].T + pose[:3, 3]
    has_depth = depth > 0
    seen = torch.ones_like(has_depth)
    newest_first = list(range(len(views) - 1, -1, -1))
    seen[has_depth] = observed_mask(world[has_depth], views, newest_first)
    block = seen.reshape(rows.numel(), cols.numel())
    row_of = torch.arange(height, device=block.device) // stride
    col_of = torch.arange(width, device=block.device) // stride
    return block[row_of[:, None], col_of[None, :]].reshape(-1).to(view.depth.device)
