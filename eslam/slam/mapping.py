"""Mapping: jointly optimise the map and the window's keyframe poses (method.md section 5).

Each iteration draws the same number of rays from every keyframe of the window (the
total is ``mapping.rays``), renders them with the field, and steps Adam on the shared
loss with the mapping weights. Planes, decoders (and beta) and, when enabled, the
poses of every window keyframe but the oldest are optimised together (the paper's
joint optimisation); the oldest pose stays fixed to anchor the window. A fresh
optimiser is made per call, as in the release, so the map file needs no optimiser state.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from eslam.config import LossConfig, MappingConfig, RenderConfig
from eslam.field.scene_field import SceneField
from eslam.geometry.pose import pose_from_quaternion_translation, quaternion_translation_from_pose
from eslam.losses import compute_losses
from eslam.render.renderer import render_rays
from eslam.slam.views import View, concatenate_rays, sample_view_rays


@dataclass(frozen=True)
class MappingSettings:
    """What ``map_window`` needs from the configuration."""

    mapping: MappingConfig
    render: RenderConfig
    loss: LossConfig


@dataclass(frozen=True, eq=False)
class MappingResult:
    """Outcome of one mapping call.

    Attributes:
        poses: (W, 4, 4) refined camera-to-world poses of the window (fixed ones unchanged).
        loss: loss of the last iteration (nan when no iteration ran).
    """

    poses: torch.Tensor
    loss: float


def map_window(
    field: SceneField,
    views: list[View],
    poses: torch.Tensor,
    optimise: list[bool],
    settings: MappingSettings,
    iterations: int,
    lr_factor: float,
    generator: torch.Generator,
) -> MappingResult:
    """Optimise ``field`` (in place) and the poses flagged in ``optimise`` on a window.

    Args:
        views: the window's keyframes as Views (W of them).
        poses: (W, 4, 4) their current camera-to-world poses.
        optimise: per keyframe, whether its pose is refined.
        iterations: optimisation steps.
        lr_factor: multiplier of the map learning rates (5 for the first frame, release).
    """
    config = settings.mapping
    poses = poses.detach().clone()
    movable = [i for i, flag in enumerate(optimise) if flag]
    groups = [
        {"params": field.plane_parameters(), "lr": config.lr_planes * lr_factor},
        {"params": field.decoder_parameters(), "lr": config.lr_decoders * lr_factor},
    ]
    quaternions = translations = None
    if movable:
        quaternions, translations = quaternion_translation_from_pose(poses[movable])
        quaternions = quaternions.clone().requires_grad_(True)
        translations = translations.clone().requires_grad_(True)
        groups.append({"params": [quaternions, translations], "lr": config.lr_poses})
    optimiser = torch.optim.Adam(groups)
    rays_per_view = max(1, config.rays // len(views))
    loss = float("nan")
    for _ in range(iterations):
        current = poses
        if movable:
            refined = pose_from_quaternion_translation(quaternions, translations)
            current = poses.index_put((torch.tensor(movable, device=poses.device),), refined)
        rays = concatenate_rays(
            [
                sample_view_rays(view, current[k], rays_per_view, generator)
                for k, view in enumerate(views)
            ]
        )
        output = render_rays(field, rays, settings.render, perturb=True, generator=generator)
        terms = compute_losses(output, rays, config.weights, field.truncation, settings.loss)
        optimiser.zero_grad(set_to_none=True)
        terms.total.backward()
        optimiser.step()
        loss = float(terms.total.detach())
    if movable:
        with torch.no_grad():
            poses[movable] = pose_from_quaternion_translation(quaternions, translations)
    return MappingResult(poses=poses, loss=loss)
