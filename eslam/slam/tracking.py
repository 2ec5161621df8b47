"""Camera tracking: optimise one frame's pose against the frozen map (method.md section 4).

The pose is a quaternion (x, y, z, w) and a translation, optimised with Adam (fresh
optimiser per frame, betas from the config) for a fixed number of iterations; each
iteration samples rays away from the image border, renders them, and steps on the
shared loss (:func:`eslam.losses.compute_losses`) with tracking weights and the 10x
median outlier rejection. The pose with the lowest loss seen is returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from eslam.config import LossConfig, RenderConfig, TrackingConfig
from eslam.geometry.pose import pose_from_quaternion_translation, quaternion_translation_from_pose
from eslam.losses import compute_losses
from eslam.render.renderer import SceneFieldLike, render_rays
from eslam.slam.views import View, sample_view_rays


@dataclass(frozen=True)
class TrackingSettings:
    """What ``track_frame`` needs from the configuration."""

    tracking: TrackingConfig
    render: RenderConfig
    loss: LossConfig


@dataclass(frozen=True, eq=False)
class TrackingResult:
    """Outcome of tracking one frame.

    Attributes:
        pose: (4, 4) float32 camera-to-world pose with the lowest loss.
        loss: that lowest loss.
    """

    pose: torch.Tensor
    loss: float


class frozen:
    """Context: parameters of ``module`` do not require gradients inside the block."""

    def __init__(self, module: torch.nn.Module) -> None:
        self.module = module
        self.flags: list[bool] = []

    def __enter__(self) -> None:
        self.flags = [p.requires_grad for p in self.module.parameters()]
        self.module.requires_grad_(False)

    def __exit__(self, *exc: object) -> None:
        for parameter, flag in zip(self.module.parameters(), self.flags, strict=True):
            parameter.requires_grad_(flag)


def track_frame(
    field: SceneFieldLike,
    view: View,
    initial_pose: torch.Tensor,
    settings: TrackingSettings,
    generator: torch.Generator,
) -> TrackingResult:
    """Estimate the camera-to-world pose of ``view`` starting from ``initial_pose`` (4, 4).

    The field is frozen; only the 7 pose parameters receive gradients.
    """
    config = settings.tracking
    quaternion, translation = quaternion_translation_from_pose(initial_pose.detach())
    quaternion = quaternion.clone().requires_grad_(True)
    translation = translation.clone().requires_grad_(True)
    optimiser = torch.optim.Adam(
        [
            {"params": [translation], "lr": config.lr_translation},
            {"params": [quaternion], "lr": config.lr_rotation},
        ],
        betas=config.adam_betas,
    )
    best_pose = initial_pose.detach().clone()
    best_loss = float("inf")
    with frozen(field):  # type: ignore[arg-type]
        for _ in range(config.iterations):
            c2w = pose_from_quaternion_translation(quaternion, translation)
            rays = sample_view_rays(view, c2w, config.rays, generator)
            output = render_rays(field, rays, settings.render, perturb=True, generator=generator)
            terms = compute_losses(
                output,
                rays,
                config.weights,
                field.truncation,
                settings.loss,
                outlier_factor=config.outlier_factor,
            )
            loss = float(terms.total.detach())
            if loss < best_loss:
                best_loss = loss
                best_pose = c2w.detach().clone()
            optimiser.zero_grad(set_to_none=True)
            terms.total.backward()
            optimiser.step()
    return TrackingResult(pose=best_pose, loss=best_loss)
