"""A direct TSDF regression warm start for the first mapping call (no volume rendering).

Before the first frame's rendering steps, the geometry planes and the SDF decoder are
fitted to the projective truncated SDF of the first depth image: points are drawn
along the frame's rays (most within the truncation band around the measured depth, the
rest in the free space in front of it) and the field's TSDF there is regressed onto
the value the depth implies. Each point costs one geometry query: no colour branch, no
compositing along a ray, so a step over thousands of points is cheaper than a
rendering step over as many samples. The rendering steps that follow (fewer than
without the warm start) fit colour and make the rendered depth consistent.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from eslam.field.scene_field import SceneField
from eslam.slam.views import View, sample_view_rays


@dataclass(frozen=True)
class WarmStart:
    """How long and on how many points the warm start regresses.

    Attributes:
        steps: Adam steps (0 = no warm start).
        points: points per step.
        band_fraction: share of the points within the truncation band |z - D| <= T; the
            rest lie in the free space 0 < z < D - T.
        lr_factor: multiplier of the map learning rates (planes, decoders).

    The defaults were chosen on the demo scene (benchmarks/first_frame.py;
    docs/benchmarks.md, "Time to the first pose"): more free-space points and a higher
    rate than the rendering steps' 5x gave a lower held-out depth L1 (spurious zero
    crossings in front of the surface are what a band-only fit leaves).
    """

    steps: int
    points: int
    band_fraction: float = 0.25
    lr_factor: float = 20.0


def projective_tsdf(z: torch.Tensor, depth: torch.Tensor, truncation: float) -> torch.Tensor:
    """The truncated SDF a depth measurement implies at depth z along its ray, units of T.

    s*(z) = clip((D - z) / T, -1, 1): the projective TSDF of KinectFusion (Newcombe et
    al. 2011, eq. 6-7: the signed distance along the optical axis, truncated at T),
    normalised by T as the field's TSDF is. It is the value that zeroes the paper's SDF
    loss (ESLAM, Johari et al. 2023, eq. 6-8; :func:`eslam.losses.sdf_loss_terms`): in
    the band |z - D| <= T the residual z + s T - D vanishes at s = (D - z) / T, and in
    front of it (z < D - T) the free-space term (s - 1)^2 at s = 1.

    Args:
        z: (N,) depths of the points along their rays, metres.
        depth: (N,) measured depths D, metres.
        truncation: T, metres.

    Returns:
        (N,) targets in [-1, 1].
    """
    return ((depth - z) / truncation).clamp(-1.0, 1.0)


def warm_start_points(
    view: View,
    c2w: torch.Tensor,
    count: int,
    truncation: float,
    band_fraction: float,
    generator: torch.Generator,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``count`` points along rays of ``view`` seen from ``c2w`` and their TSDF targets.

    Pixels are drawn uniformly among the sampleable ones; the first
    round(band_fraction * count) points lie at z = D + T (2u - 1) (the band), the others
    at z = u max(D - T, 0) (free space), u uniform in [0, 1). Points behind the band get
    none, as the SDF loss gives them no term.

    Returns:
        (count, 3) world points and (count,) targets (:func:`projective_tsdf`).
    """
    rays = sample_view_rays(view, c2w, count, generator)
    uniform = torch.rand(count, generator=generator, device=rays.depth.device)
    band = torch.arange(count, device=rays.depth.device) < round(band_fraction * count)
    z_band = rays.depth + truncation * (2.0 * uniform - 1.0)
    z_free = uniform * (rays.depth - truncation).clamp(min=0.0)
    z = torch.where(band, z_band, z_free)
    points = rays.origins + z.unsqueeze(-1) * rays.directions
    return points, projective_tsdf(z, rays.depth, truncation)


def warm_start_optimiser(
    field: SceneField, lr_planes: float, lr_decoder: float
) -> torch.optim.Adam:
    """Adam over the geometry planes and the SDF decoder only (colour is left alone)."""
    return torch.optim.Adam(
        [
            {"params": [level.planes for level in field.geometry.levels.values()], "lr": lr_planes},
            {"params": list(field.geometry_decoder.parameters()), "lr": lr_decoder},
        ]
    )


def tsdf_warm_start(
    field: SceneField,
    view: View,
    c2w: torch.Tensor,
    plan: WarmStart,
    lr_planes: float,
    lr_decoder: float,
    generator: torch.Generator,
) -> torch.Tensor:
    """Fit ``field``'s TSDF (in place) to the projective TSDF of ``view`` at pose ``c2w``:
    :func:`tsdf_warm_start_views` with the one view."""
    return tsdf_warm_start_views(
        field, [view], c2w.unsqueeze(0), plan, lr_planes, lr_decoder, generator
    )


def tsdf_warm_start_views(
    field: SceneField,
    views: Sequence[View],
    c2ws: torch.Tensor,
    plan: WarmStart,
    lr_planes: float,
    lr_decoder: float,
    generator: torch.Generator,
) -> torch.Tensor:
    """Fit ``field``'s TSDF (in place) to the projective TSDF of ``views`` at ``c2ws``.

    Step i minimises mean_j (s(p_j) - s*_j)^2 over ``plan.points`` fresh points of view
    i mod N (:func:`warm_start_points`; the views in turn, so one view gives the first
    frame's warm start and many a map rebuilt from every keyframe after a loop
    correction, ``mapping.loops.map: rebuild``) with Adam at ``plan.lr_factor`` times
    ``lr_planes`` and ``lr_decoder``. With shared planes (ablation a) the colour branch
    reads the planes fitted here. No host synchronisation.

    Args:
        views: N views.
        c2ws: (N, 4, 4) their camera-to-world poses.

    Returns:
        0-d tensor, the loss of the last step (nan when ``plan.steps`` is 0).
    """
    if len(views) != len(c2ws) or not views:
        raise ValueError(f"{len(views)} views with {len(c2ws)} poses")
    optimiser = warm_start_optimiser(field, lr_planes * plan.lr_factor, lr_decoder * plan.lr_factor)
    loss = torch.full((), float("nan"), device=c2ws.device)
    c2ws = c2ws.detach()
    for step in range(plan.steps):
        k = step % len(views)
        points, target = warm_start_points(
            views[k], c2ws[k], plan.points, field.truncation, plan.band_fraction, generator
        )
        loss = (field.query(points, with_rgb=False).sdf - target).square().mean()
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        optimiser.step()
        loss = loss.detach()
    return loss
