"""Mapping: jointly optimise the map and the window's keyframe poses (docs/method.md section 5).

Each iteration draws the same number of rays from every keyframe of the window (the
total is ``mapping.rays``), renders them with the field, and steps Adam on the shared
loss with the mapping weights. Planes, decoders (and beta) and, when enabled, the
poses of every window keyframe but the oldest are optimised together (the paper's
joint optimisation); the oldest pose stays fixed to anchor the window. A fresh
optimiser is made per call, as in the release, so the map file needs no optimiser state.

:func:`mapping_step` is one iteration and never synchronises with the host; the
benchmarks time this same function. :func:`mapping_schedule` says how long each call
optimises (the first frame longer and faster, as the release does, or after a TSDF
warm start, :mod:`eslam.slam.mapping.warm_start`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import torch

from eslam.config import LossConfig, MappingConfig, RenderConfig
from eslam.field.scene_field import SceneField
from eslam.geometry.pose import pose_from_quaternion_translation, quaternion_translation_from_pose
from eslam.losses import compute_losses, depth_noise_weights
from eslam.slam.mapping.warm_start import WarmStart, tsdf_warm_start_views
from eslam.slam.views import (
    RayDraws,
    View,
    concatenate_rays,
    draw_rays,
    pixels_from_uniforms,
    render_drawn,
    view_rays,
)
from eslam.stages import stage


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
        loss: 0-d tensor, loss of the last iteration (nan when no iteration ran).
    """

    poses: torch.Tensor
    loss: torch.Tensor


@dataclass(frozen=True)
class MappingSchedule:
    """How one mapping call optimises.

    Attributes:
        iterations: optimisation steps.
        lr_factor: multiplier of the map learning rates at the first step.
        rays: rays per step over the whole window.
        lr_decay: the map learning rates end at this fraction of their start (cosine).
        warm_start: a TSDF regression on the window's views before the rendering steps
            (:mod:`eslam.slam.mapping.warm_start`; the first call's on its one view, a
            later call's in real time with ``realtime_warm_start``), or None.
    """

    iterations: int
    lr_factor: float
    rays: int
    lr_decay: float = 1.0
    warm_start: WarmStart | None = None

    def lr_scale(self, step: int) -> float:
        """Map learning-rate multiplier at ``step`` (0-based) relative to the start:
        d + (1 - d) (1 + cos(pi t)) / 2 with t = step / (iterations - 1), d = lr_decay."""
        if self.lr_decay == 1.0 or self.iterations < 2:
            return 1.0
        t = step / (self.iterations - 1)
        return self.lr_decay + (1.0 - self.lr_decay) * 0.5 * (1.0 + math.cos(math.pi * t))


LATER_WARM_START_LR = 5.0
"""The learning-rate factor of a later call's warm start (``realtime_warm_start``): the
first frame's 20x (:class:`~eslam.slam.mapping.warm_start.WarmStart`) fits a blank map;
a map already fitted takes a gentler rate (docs/results.md, "What we tried")."""


def mapping_schedule(
    config: MappingConfig, first: bool, real_time: bool = False
) -> MappingSchedule:
    """The schedule of a mapping call.

    The first call (the map is empty) runs ``first_iterations`` at ``first_lr_factor``
    times the learning rates (release: 1000 at 5x, constant), with ``first_rays`` rays
    and the rates decaying to ``first_lr_decay`` of their start, after the TSDF warm start
    when ``first_warm_start`` is tsdf; later calls run ``iterations`` at 1x with ``rays``.
    While frames arrive in ``real_time``, ``realtime_first_iterations`` and
    ``realtime_iterations`` replace the two step counts when set, and later calls begin
    with ``realtime_warm_start`` TSDF steps over their window when that is above 0.
    """
    if first:
        warm = (
            WarmStart(config.first_warm_start_steps, config.first_warm_start_points)
            if config.first_warm_start == "tsdf"
            else None
        )
        first_iterations = config.first_iterations
        if real_time and config.realtime_first_iterations is not None:
            first_iterations = config.realtime_first_iterations
        return MappingSchedule(
            iterations=first_iterations,
            lr_factor=config.first_lr_factor,
            rays=config.first_rays or config.rays,
            lr_decay=config.first_lr_decay,
            warm_start=warm,
        )
    iterations = config.iterations
    if real_time and config.realtime_iterations is not None:
        iterations = config.realtime_iterations
    warm = None
    if real_time and config.realtime_warm_start > 0:
        steps, points = config.realtime_warm_start, config.first_warm_start_points
        warm = WarmStart(steps, points, lr_factor=LATER_WARM_START_LR)
    return MappingSchedule(iterations=iterations, lr_factor=1.0, rays=config.rays, warm_start=warm)


@dataclass(frozen=True, eq=False)
class WindowPoses:
    """The window's poses as the optimiser sees them.

    Attributes:
        fixed: (W, 4, 4) poses at the start of the call (rows of refined poses unused).
        movable: (M,) int64 window rows whose poses are refined (on the device).
        quaternions: (M, 4) leaf tensor with gradients, or None when M = 0.
        translations: (M, 3) leaf tensor with gradients, or None when M = 0.
    """

    fixed: torch.Tensor
    movable: torch.Tensor
    quaternions: torch.Tensor | None
    translations: torch.Tensor | None

    @classmethod
    def create(cls, poses: torch.Tensor, optimise: list[bool]) -> WindowPoses:
        """Variables for the rows of ``poses`` (W, 4, 4) flagged in ``optimise``."""
        fixed = poses.detach().clone()
        rows = [i for i, flag in enumerate(optimise) if flag]
        movable = torch.tensor(rows, dtype=torch.int64, device=fixed.device)
        if not rows:
            return cls(fixed, movable, None, None)
        quaternions, translations = quaternion_translation_from_pose(fixed[rows])
        return cls(
            fixed,
            movable,
            quaternions.clone().requires_grad_(True),
            translations.clone().requires_grad_(True),
        )

    def parameters(self) -> list[torch.Tensor]:
        """The pose variables (empty when no pose is refined)."""
        if self.quaternions is None or self.translations is None:
            return []
        return [self.quaternions, self.translations]

    def current(self) -> torch.Tensor:
        """(W, 4, 4) poses with the refined rows, differentiable w.r.t. the variables."""
        if self.quaternions is None or self.translations is None:
            return self.fixed
        refined = pose_from_quaternion_translation(self.quaternions, self.translations)
        return self.fixed.index_put((self.movable,), refined)


class PoseWindow(Protocol):
    """What a mapping step needs of the window's poses (:class:`WindowPoses`, or the
    graph-ready :class:`~eslam.slam.static_steps.SlotPoses`)."""

    fixed: torch.Tensor

    def parameters(self) -> list[torch.Tensor]:
        """The pose variables the optimiser refines."""
        ...

    def current(self) -> torch.Tensor:
        """(W', 4, 4) poses, row k the pose of the step's view k (W' >= the views:
        the graph-ready window has slots to spare), differentiable w.r.t. the variables."""
        ...


def map_learning_rates(config: MappingConfig, lr_factor: float) -> tuple[float, float]:
    """The start learning rates of the planes and of the decoders (and beta): ``lr_factor``
    times their configured rates (the poses keep ``lr_poses``)."""
    return config.lr_planes * lr_factor, config.lr_decoders * lr_factor


def mapping_optimiser(
    field: SceneField, window: PoseWindow, config: MappingConfig, lr_factor: float
) -> torch.optim.Adam:
    """Adam over planes, decoders (and beta) at ``lr_factor`` times their rates, and poses."""
    planes, decoders = map_learning_rates(config, lr_factor)
    groups = [
        {"params": field.plane_parameters(), "lr": planes},
        {"params": field.decoder_parameters(), "lr": decoders},
    ]
    if window.parameters():
        groups.append({"params": window.parameters(), "lr": config.lr_poses})
    return torch.optim.Adam(groups)


def mapping_loss(
    field: SceneField,
    views: list[View],
    window: PoseWindow,
    draws: RayDraws,
    settings: MappingSettings,
) -> torch.Tensor:
    """The mapping loss over the window, a pure function of tensors (compilable).

    Rays through the pixels ``draws`` chose in each view at its current pose, rendered
    with its jitter, scored by the shared loss with the mapping weights; with
    ``mapping.weigh_depth_noise`` each ray's depth-derived terms weigh D^-4
    (:func:`~eslam.losses.depth_noise_weights`).
    """
    with stage("ray sampling"):
        current = window.current()
        rays = concatenate_rays(
            [
                view_rays(view, current[k], pixels_from_uniforms(view, draws.pixels[k]))
                for k, view in enumerate(views)
            ]
        )
    output = render_drawn(field, rays, draws, settings.render)
    with stage("loss"):
        weights = depth_noise_weights(rays.depth) if settings.mapping.weigh_depth_noise else None
        terms = compute_losses(
            output,
            rays,
            settings.mapping.weights,
            field.truncation,
            settings.loss,
            ray_weights=weights,
        )
    return terms.total


def mapping_step(
    field: SceneField,
    views: list[View],
    window: PoseWindow,
    optimiser: torch.optim.Optimizer,
    settings: MappingSettings,
    generator: torch.Generator,
    rays: int | None = None,
) -> torch.Tensor:
    """One mapping iteration over the window; returns the loss (0-d, detached, before the step).

    ``rays // W`` rays (default ``mapping.rays``) from each of the W views. No host
    synchronisation and fixed shapes.
    """
    per_view = max(1, (rays or settings.mapping.rays) // len(views))
    device = window.fixed.device
    with stage("ray sampling"):
        draws = draw_rays(len(views), per_view, settings.render, generator, device)
    loss = mapping_loss(field, views, window, draws, settings)
    optimiser.zero_grad(set_to_none=True)
    with stage("backward"):
        loss.backward()
    with stage("optimiser step"):
        optimiser.step()
    return loss.detach()


def warm_start_window(
    field: SceneField,
    views: list[View],
    poses: torch.Tensor,
    settings: MappingSettings,
    schedule: MappingSchedule,
    generator: torch.Generator,
) -> None:
    """The TSDF warm start of ``schedule`` (if it has one) on the window's ``views`` at
    ``poses``, in turn (the first call: its one view): what a mapping call runs before its
    rendering steps (:mod:`eslam.slam.mapping.warm_start`)."""
    if schedule.warm_start is not None:
        tsdf_warm_start_views(
            field,
            views,
            poses,
            schedule.warm_start,
            settings.mapping.lr_planes,
            settings.mapping.lr_decoders,
            generator,
        )


def map_window(
    field: SceneField,
    views: list[View],
    poses: torch.Tensor,
    optimise: list[bool],
    settings: MappingSettings,
    schedule: MappingSchedule,
    generator: torch.Generator,
    on_step: Callable[[int], None] | None = None,
) -> MappingResult:
    """Optimise ``field`` (in place) and the poses flagged in ``optimise`` on a window.

    Args:
        views: the window's keyframes as Views (W of them).
        poses: (W, 4, 4) their current camera-to-world poses.
        optimise: per keyframe, whether its pose is refined.
        schedule: iterations, learning-rate factor and decay, rays
            (:func:`mapping_schedule`), and the TSDF warm start run first on
            ``views[0]`` at ``poses[0]`` when it has one.
        on_step: called with k after the k-th iteration (1, 2, ...): a count for
            progress reports, never a value read from the device (no host sync).
    """
    warm_start_window(field, views, poses, settings, schedule, generator)
    window = WindowPoses.create(poses, optimise)
    optimiser = mapping_optimiser(field, window, settings.mapping, schedule.lr_factor)
    map_groups = optimiser.param_groups[:2]  # planes, decoders (poses keep their rate)
    start_lrs = [group["lr"] for group in map_groups]
    loss = torch.full((), float("nan"), device=window.fixed.device)
    for step in range(schedule.iterations):
        scale = schedule.lr_scale(step)
        for group, start in zip(map_groups, start_lrs, strict=True):
            group["lr"] = start * scale
        loss = mapping_step(
            field, views, window, optimiser, settings, generator, rays=schedule.rays
        )
        if on_step is not None:
            on_step(step + 1)
    with torch.no_grad():
        refined = window.current().detach().clone()
    return MappingResult(poses=refined, loss=loss)
