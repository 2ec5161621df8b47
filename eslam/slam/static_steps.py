"""Graph-ready tracking and mapping iterations: every input in a tensor that stays put.

A CUDA graph replays its kernels on the addresses it was captured with, so an
iteration that is to be captured may only read and write tensors that outlive it and
are refilled in place. This module runs the eager steps
(:func:`~eslam.slam.tracking.render.tracking_step`, :func:`~eslam.slam.mapping.mapper.mapping_step`)
on such tensors:

- static views: a frame's (or a window's) images copied into buffers of the camera's
  size (:func:`static_view`, :func:`load_view`);
- static pose variables, overwritten in place at the start of a frame or mapping call;
- a fixed number of window slots (``mapping.window``): view buffers and pose variables;
  a window of W keyframes uses the first W, and the slots beyond it and the rows that
  are not refined are held by a mask (masks as weights, :class:`SlotPoses`): such a row
  gets a zero gradient, so Adam leaves it exactly where it was;
- one Adam for the tracker and one for mapping, whose learning rates are 0-d tensors
  (filled between iterations; capturable on CUDA), reset in place (moments and step
  counts zeroed, :func:`reset_adam`) instead of a new optimiser per frame or call;
- the tracker's best loss and pose kept in place (:func:`~eslam.slam.tracking.render.keep_best`).

The random draws stay inside the step (same generator, same order, same shapes as the
eager step), so the numbers drawn are the eager path's. That is why the rays are not
padded to the full slots: padding would change how many numbers a step draws, and with
them every later draw. The step's ray count (``rays // W`` per view) follows W, so a
graph is captured per window size; the buffers, the pose variables and the optimiser
are shared by all of them.

Run eagerly (any device) the iterations equal the eager ones within float tolerance
(tests/slam/test_static_steps.py); :mod:`eslam.slam.cuda_graphs` captures one of them as a
CUDA graph and replays it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from eslam.field.scene_field import SceneField
from eslam.geometry.pose import pose_from_quaternion_translation, quaternion_translation_from_pose
from eslam.render.renderer import SceneFieldLike
from eslam.slam.mapping.mapper import (
    MappingResult,
    MappingSchedule,
    MappingSettings,
    map_learning_rates,
    mapping_optimiser,
    mapping_step,
)
from eslam.slam.tracking.base import TrackingResult
from eslam.slam.tracking.render import (
    PoseVariables,
    TrackingSettings,
    frozen,
    keep_best,
    pose_optimiser,
    tracking_step,
)
from eslam.slam.views import View


def field_tensors(field: torch.nn.Module) -> list[torch.Tensor]:
    """The field's parameters and buffers: what a captured step reads by address (plane
    growth and a rolled-back field replace them)."""
    return [*field.parameters(), *field.buffers()]


def same_tensors(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
    """Whether two lists hold the same tensor objects (identity, not values)."""
    return len(a) == len(b) and all(x is y for x, y in zip(a, b, strict=True))


def static_view(like: View) -> View:
    """Buffers shaped as ``like`` (its images not copied; fill them with :func:`load_view`).

    ``count`` is a view of the last entry of ``cumulative``, so it follows every load.
    """
    cumulative = torch.empty_like(like.cumulative)
    return View(
        rgb=torch.empty_like(like.rgb),
        depth=torch.empty_like(like.depth),
        directions=torch.empty_like(like.directions),
        cumulative=cumulative,
        count=cumulative[-1],
    )


def view_shape(view: View) -> tuple[tuple[int, ...], ...]:
    """The shapes a static view must have to hold ``view``."""
    return (tuple(view.rgb.shape), tuple(view.directions.shape))


def load_view(static: View, view: View) -> None:
    """Copy the images and sampling table of ``view`` into the buffers of ``static``."""
    with torch.no_grad():
        static.rgb.copy_(view.rgb)
        static.depth.copy_(view.depth)
        static.directions.copy_(view.directions)
        static.cumulative.copy_(view.cumulative)


def static_adam(optimiser: torch.optim.Adam) -> torch.optim.Adam:
    """The Adam of ``optimiser`` (same groups, betas and eps) with each group's learning
    rate a 0-d tensor on the parameters' device, filled in place (:func:`set_learning_rates`)
    so a captured step reads the current rate; capturable on CUDA.

    The rates are float64 on the CPU, where Adam then does the eager step's float64
    arithmetic, and float32 elsewhere (capturable Adam's own dtype).
    """
    device = optimiser.param_groups[0]["params"][0].device
    dtype = torch.float64 if device.type == "cpu" else torch.float32
    groups = [
        {"params": group["params"], "lr": torch.tensor(group["lr"], dtype=dtype, device=device)}
        for group in optimiser.param_groups
    ]
    defaults = optimiser.defaults
    return torch.optim.Adam(
        groups, betas=defaults["betas"], eps=defaults["eps"], capturable=device.type == "cuda"
    )


def set_learning_rates(optimiser: torch.optim.Optimizer, rates: list[float]) -> None:
    """Fill the tensor learning rates of the first ``len(rates)`` groups, in place."""
    for group, rate in zip(optimiser.param_groups, rates, strict=False):
        group["lr"].fill_(rate)


def reset_adam(optimiser: torch.optim.Optimizer) -> None:
    """Zero every moment and step count in place: the next step is a new Adam's first.

    A new Adam starts with step 0 and zero moments; the state its first step created
    keeps its addresses (a captured step reads and writes them).
    """
    with torch.no_grad():
        for state in optimiser.state.values():
            for value in state.values():
                if isinstance(value, torch.Tensor):
                    value.zero_()


def load_pose_variables(
    quaternion: torch.Tensor, translation: torch.Tensor, poses: torch.Tensor
) -> None:
    """Overwrite the variables with the quaternions and translations of ``poses`` (..., 4, 4)."""
    with torch.no_grad():
        q, t = quaternion_translation_from_pose(poses.detach())
        quaternion.copy_(q)
        translation.copy_(t)


class StaticTracking:
    """The rendering tracker's iterations on static tensors for views shaped as ``like``.

    Args:
        settings: the rendering tracker's settings.
        like: a view of the camera (sets the buffers' shapes and device).
    """

    def __init__(self, settings: TrackingSettings, like: View) -> None:
        device = like.depth.device
        self.settings = settings
        self.shape = view_shape(like)
        self.view = static_view(like)
        self.variables = PoseVariables.from_pose(torch.eye(4, device=device))
        self.optimiser = static_adam(pose_optimiser(self.variables, settings.tracking))
        self.best_loss = torch.full((), float("inf"), device=device)
        self.best_pose = torch.eye(4, device=device)

    def start(self, view: View, initial_pose: torch.Tensor) -> None:
        """Load a frame: its view, the starting pose, a fresh optimiser, no best yet."""
        load_view(self.view, view)
        load_pose_variables(self.variables.quaternion, self.variables.translation, initial_pose)
        reset_adam(self.optimiser)
        self.best_loss.fill_(float("inf"))
        self.best_pose.copy_(initial_pose.detach())

    def step(self, field: SceneFieldLike, generator: torch.Generator) -> None:
        """One iteration (:func:`~eslam.slam.tracking.render.tracking_step`), the best kept
        in place.

        Call it with the field frozen (:class:`~eslam.slam.tracking.render.frozen`).
        """
        loss, pose = tracking_step(
            field, self.view, self.variables, self.optimiser, self.settings, generator
        )
        best_loss, best_pose = keep_best(self.best_loss, self.best_pose, loss, pose)
        self.best_loss.copy_(best_loss)
        self.best_pose.copy_(best_pose)

    def result(self) -> TrackingResult:
        """The lowest-loss pose and its loss so far (copies: the buffers are reused)."""
        return TrackingResult(pose=self.best_pose.clone(), loss=self.best_loss.clone())


@dataclass(frozen=True, eq=False)
class SlotPoses:
    """The window's poses as variables in S slots; rows not refined are held by a mask.

    A call with W <= S keyframes uses slots 0..W-1; the others, like the rows that are
    not refined, are masked out (masks as weights).

    Attributes:
        fixed: (S, 4, 4) poses at the start of the call.
        refine: (S,) bool, the rows whose poses are refined (never a slot beyond W).
        quaternions: (S, 4) leaf tensor with gradients.
        translations: (S, 3) leaf tensor with gradients.
    """

    fixed: torch.Tensor
    refine: torch.Tensor
    quaternions: torch.Tensor
    translations: torch.Tensor

    @classmethod
    def empty(cls, slots: int, device: torch.device) -> SlotPoses:
        """Variables for ``slots`` poses (identity; fill them with :meth:`load`)."""
        eye = torch.eye(4, device=device).repeat(slots, 1, 1)
        quaternions, translations = quaternion_translation_from_pose(eye)
        return cls(
            eye,
            torch.zeros(slots, dtype=torch.bool, device=device),
            quaternions.clone().requires_grad_(True),
            translations.clone().requires_grad_(True),
        )

    def load(self, poses: torch.Tensor, optimise: list[bool]) -> None:
        """Start a call at ``poses`` (W, 4, 4) in the first W slots, refining the rows
        flagged in ``optimise``."""
        size = len(poses)
        mask = [*optimise, *([False] * (len(self.refine) - size))]
        with torch.no_grad():
            self.fixed[:size].copy_(poses.detach())
            self.refine.copy_(torch.tensor(mask, dtype=torch.bool))
            load_pose_variables(self.quaternions[:size], self.translations[:size], poses)

    def parameters(self) -> list[torch.Tensor]:
        """The pose variables (all slots; those not refined get zero gradients)."""
        return [self.quaternions, self.translations]

    def current(self) -> torch.Tensor:
        """(S, 4, 4) refined rows from the variables, the others the fixed poses:
        where(refine, pose(q, t), fixed), so a fixed row passes no gradient to q, t."""
        refined = pose_from_quaternion_translation(self.quaternions, self.translations)
        return torch.where(self.refine[:, None, None], refined, self.fixed)


class StaticMapping:
    """Mapping iterations on static tensors: ``slots`` view buffers and pose slots, a
    call on W <= ``slots`` keyframes using the first W (:class:`SlotPoses`).

    One optimiser (its state reset in place) serves every window size. It holds the
    field's parameters: build a new StaticMapping when they are replaced (plane growth,
    a rolled-back field); :meth:`fits` says whether this one still fits (it holds the
    field's tensors, so a replaced one is never mistaken for its successor).

    Args:
        settings: the mapping settings.
        field: the field to optimise.
        like: a view of the camera (sets the buffers' shapes and device).
        slots: the most keyframes a window may have (``mapping.window``).
    """

    def __init__(
        self, settings: MappingSettings, field: SceneField, like: View, slots: int
    ) -> None:
        device = like.depth.device
        self.settings = settings
        self.tensors = field_tensors(field)
        self.shape = view_shape(like)
        self.views = [static_view(like) for _ in range(slots)]
        self.window = SlotPoses.empty(slots, device)
        self.optimiser = static_adam(mapping_optimiser(field, self.window, settings.mapping, 1.0))
        self.loss = torch.full((), float("nan"), device=device)
        self.size = 0

    def fits(self, field: SceneField, views: list[View]) -> bool:
        """Whether these buffers and optimiser serve ``field`` on a window like ``views``."""
        return (
            same_tensors(field_tensors(field), self.tensors)
            and len(views) <= len(self.views)
            and all(view_shape(view) == self.shape for view in views)
        )

    def start(
        self, views: list[View], poses: torch.Tensor, optimise: list[bool], lr_factor: float
    ) -> None:
        """Load a call: the views and poses into the first slots, a fresh optimiser at
        ``lr_factor``."""
        self.size = len(views)
        for static, view in zip(self.views, views, strict=False):
            load_view(static, view)
        self.window.load(poses, optimise)
        reset_adam(self.optimiser)
        mapping = self.settings.mapping
        set_learning_rates(
            self.optimiser, [*map_learning_rates(mapping, lr_factor), mapping.lr_poses]
        )
        self.loss.fill_(float("nan"))

    def set_scale(self, lr_factor: float, scale: float) -> None:
        """The map learning rates at ``scale`` times their start (the poses keep theirs):
        the same products the eager loop forms."""
        starts = map_learning_rates(self.settings.mapping, lr_factor)
        set_learning_rates(self.optimiser, [start * scale for start in starts])

    def step(self, field: SceneField, generator: torch.Generator, rays: int, size: int) -> None:
        """One iteration (:func:`~eslam.slam.mapping.mapper.mapping_step`) over the first ``size``
        slots, its loss kept in place."""
        loss = mapping_step(
            field,
            self.views[:size],
            self.window,
            self.optimiser,
            self.settings,
            generator,
            rays=rays,
        )
        self.loss.copy_(loss)

    def result(self) -> MappingResult:
        """The refined poses of the call's keyframes and the last loss (copies: the
        buffers are reused)."""
        with torch.no_grad():
            poses = self.window.current()[: self.size].detach().clone()
        return MappingResult(poses=poses, loss=self.loss.clone())


def run_tracking(
    tracking: StaticTracking,
    field: SceneFieldLike,
    view: View,
    initial_pose: torch.Tensor,
    iterate: Callable[[], None],
) -> TrackingResult:
    """Track a frame on ``tracking``'s buffers, as :func:`~eslam.slam.tracking.render.track_frame`.

    ``iterate`` runs one iteration (``tracking.step`` on the run's generator, or a graph
    replay of it); the field is frozen meanwhile.
    """
    tracking.start(view, initial_pose)
    with frozen(field):  # type: ignore[arg-type]
        for _ in range(tracking.settings.tracking.iterations):
            iterate()
    return tracking.result()


def run_mapping(
    mapping: StaticMapping,
    views: list[View],
    poses: torch.Tensor,
    optimise: list[bool],
    schedule: MappingSchedule,
    iterate: Callable[[], None],
    on_step: Callable[[int], None] | None = None,
) -> MappingResult:
    """A mapping call on ``mapping``'s buffers, as :func:`~eslam.slam.mapping.mapper.map_window`.

    ``iterate`` runs one iteration (``mapping.step`` on the run's generator, or a graph
    replay of it); the map learning rates follow ``schedule`` between iterations.
    """
    mapping.start(views, poses, optimise, schedule.lr_factor)  # the rates at scale 1
    scale = 1.0
    for step in range(schedule.iterations):
        if schedule.lr_scale(step) != scale:  # fill the rates only when they change
            scale = schedule.lr_scale(step)
            mapping.set_scale(schedule.lr_factor, scale)
        iterate()
        if on_step is not None:
            on_step(step + 1)
    return mapping.result()
