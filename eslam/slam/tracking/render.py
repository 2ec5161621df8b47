"""The rendering tracker (``tracking.method: render``): Adam on the rendering loss.

docs/method.md section 4. The pose is a quaternion (x, y, z, w) and a translation,
optimised with Adam (fresh optimiser per frame, betas from the config) for a fixed
number of iterations; each iteration samples rays away from the image border, renders
them, and steps on the shared loss (:func:`eslam.losses.compute_losses`) with tracking
weights and the 10x median outlier rejection. The pose with the lowest loss seen is
returned.

:func:`tracking_step` is one iteration and never synchronises with the host: the
best loss and pose are kept on the device (:func:`keep_best`), so a frame's iterations
queue up on a GPU without waiting. The benchmarks time this same function.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import field as dataclass_field

import torch

from eslam.config import LossConfig, RenderConfig, RenderTrackerConfig
from eslam.geometry.pose import pose_from_quaternion_translation, quaternion_translation_from_pose
from eslam.losses import compute_losses
from eslam.render.renderer import SceneFieldLike
from eslam.slam.tracking.base import TrackingResult
from eslam.slam.views import (
    RayDraws,
    View,
    draw_rays,
    pixels_from_uniforms,
    render_drawn,
    view_rays,
)
from eslam.stages import stage


@dataclass(frozen=True)
class TrackingSettings:
    """What the rendering tracker needs from the configuration."""

    tracking: RenderTrackerConfig
    render: RenderConfig
    loss: LossConfig


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


@dataclass(frozen=True, eq=False)
class PoseVariables:
    """A pose as the optimiser sees it: a quaternion (x, y, z, w) and a translation.

    Attributes:
        quaternion: (4,) leaf tensor with gradients (normalised when the pose is built).
        translation: (3,) leaf tensor with gradients, metres.
    """

    quaternion: torch.Tensor
    translation: torch.Tensor

    @classmethod
    def from_pose(cls, pose: torch.Tensor) -> PoseVariables:
        """Variables starting at the (4, 4) ``pose``."""
        quaternion, translation = quaternion_translation_from_pose(pose.detach())
        return cls(
            quaternion.clone().requires_grad_(True), translation.clone().requires_grad_(True)
        )

    def pose(self) -> torch.Tensor:
        """(4, 4) camera-to-world pose, differentiable with respect to the variables."""
        return pose_from_quaternion_translation(self.quaternion, self.translation)


def pose_optimiser(variables: PoseVariables, config: RenderTrackerConfig) -> torch.optim.Adam:
    """Adam over the translation and quaternion with their own learning rates (release)."""
    return torch.optim.Adam(
        [
            {"params": [variables.translation], "lr": config.lr_translation},
            {"params": [variables.quaternion], "lr": config.lr_rotation},
        ],
        betas=config.adam_betas,
    )


def tracking_loss(
    field: SceneFieldLike,
    view: View,
    variables: PoseVariables,
    draws: RayDraws,
    settings: TrackingSettings,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The tracking loss at the current pose, a pure function of tensors (compilable).

    Rays through the pixels ``draws`` chose, rendered with its jitter, scored by the
    shared loss with tracking weights and outlier rejection.

    Returns:
        The total loss (0-d) and the (4, 4) pose it was computed at, both with gradients.
    """
    config = settings.tracking
    with stage("ray sampling"):
        c2w = variables.pose()
        rays = view_rays(view, c2w, pixels_from_uniforms(view, draws.pixels[0]))
    output = render_drawn(field, rays, draws, settings.render)
    with stage("loss"):
        terms = compute_losses(
            output,
            rays,
            config.weights,
            field.truncation,
            settings.loss,
            outlier_factor=config.outlier_factor,
        )
    return terms.total, c2w


TrackingLoss = Callable[..., tuple[torch.Tensor, torch.Tensor]]
""":func:`tracking_loss` or a compiled version of it (:func:`compiled_tracking_loss`)."""


def compiled_tracking_loss(backend: str = "inductor") -> TrackingLoss:
    """:func:`tracking_loss` through ``torch.compile`` (``compute.compile: tracking``).

    Its speed against eager and its compile time: benchmarks/bench_compile.py,
    docs/benchmarks.md "torch.compile"; the loss traces without a graph break. Shapes
    are static (``dynamic=False``): a new image size or plane growth compiles again.
    """
    return torch.compile(tracking_loss, backend=backend, dynamic=False)


def tracking_step(
    field: SceneFieldLike,
    view: View,
    variables: PoseVariables,
    optimiser: torch.optim.Optimizer,
    settings: TrackingSettings,
    generator: torch.Generator,
    loss_function: TrackingLoss = tracking_loss,
) -> tuple[torch.Tensor, torch.Tensor]:
    """One tracking iteration: draw the rays, take the loss, step Adam.

    No host synchronisation: no ``float()``, ``.item()`` or ``bool()`` of device
    tensors, fixed shapes (``settings.tracking.rays`` rays). Call it with the field
    frozen (:class:`frozen`).

    Returns:
        The loss (0-d, detached) and the (4, 4) pose it was computed at (detached),
        both before the step.
    """
    device = view.depth.device
    with stage("ray sampling"):
        draws = draw_rays(1, settings.tracking.rays, settings.render, generator, device)
    loss, c2w = loss_function(field, view, variables, draws, settings)
    optimiser.zero_grad(set_to_none=True)
    with stage("backward"):
        loss.backward()
    with stage("optimiser step"):
        optimiser.step()
    return loss.detach(), c2w.detach()


def keep_best(
    best_loss: torch.Tensor, best_pose: torch.Tensor, loss: torch.Tensor, pose: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The lower of two (loss, pose) pairs, chosen on the device (ties keep the old pair)."""
    better = loss < best_loss
    return torch.where(better, loss, best_loss), torch.where(better, pose, best_pose)


def track_frame(
    field: SceneFieldLike,
    view: View,
    initial_pose: torch.Tensor,
    settings: TrackingSettings,
    generator: torch.Generator,
    loss_function: TrackingLoss = tracking_loss,
) -> TrackingResult:
    """Estimate the camera-to-world pose of ``view`` starting from ``initial_pose`` (4, 4).

    The field is frozen; only the 7 pose parameters receive gradients. ``loss_function``
    is :func:`tracking_loss` or its compiled version.
    """
    variables = PoseVariables.from_pose(initial_pose)
    optimiser = pose_optimiser(variables, settings.tracking)
    best_pose = initial_pose.detach().clone()
    best_loss = torch.full((), float("inf"), device=best_pose.device)
    with frozen(field):  # type: ignore[arg-type]
        for _ in range(settings.tracking.iterations):
            loss, pose = tracking_step(
                field, view, variables, optimiser, settings, generator, loss_function
            )
            best_loss, best_pose = keep_best(best_loss, best_pose, loss, pose)
    return TrackingResult(pose=best_pose, loss=best_loss)


@dataclass(frozen=True)
class RenderTracker:
    """The paper's tracker behind the :class:`~eslam.slam.tracking.base.Tracker` protocol.

    ``loss_function``: :func:`tracking_loss`, or its compiled version with
    ``compute.compile: tracking``.
    """

    settings: TrackingSettings
    loss_function: TrackingLoss = dataclass_field(default=tracking_loss, compare=False)

    def track(
        self,
        field: SceneFieldLike,
        view: View,
        initial_pose: torch.Tensor,
        generator: torch.Generator,
    ) -> TrackingResult:
        """Pose of ``view`` from ``initial_pose`` by :func:`track_frame`."""
        return track_frame(field, view, initial_pose, self.settings, generator, self.loss_function)
