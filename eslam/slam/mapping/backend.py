"""The mapping back end: which frames become keyframes, and the mapping call on each.

:class:`KeyframeBackEnd` (``mapping.back_end: keyframes``, the paper's) builds the
field from the first frame with depth (when ``scene.bound`` is not set), makes every
``mapping.every``-th tracked frame a keyframe (and every frame the front end recovered
after a failed try, :mod:`eslam.slam.tracking.recovery`, and with
``mapping.keyframe_coverage`` every frame with less than that share in observed space,
so that the map grows into what the camera turned to), grows the bound to hold its depth
(:func:`~eslam.slam.mapping.bounds_policy.cover_keyframe`), chooses the window
(``mapping.selection``), keeps the window's oldest keyframe fixed, and runs the mapper
(eager, or CUDA-graphed with ``compute.cuda_graphs``:
:class:`~eslam.slam.cuda_graphs.WindowMapper`). At the end of the stream its last frame
is mapped too. Mapping calls are reported to the run's observers.

Its state between frames lives in the run's :class:`~eslam.slam.state.SLAMState`
(the keyframes, the window strategy, and ``components["back_end"]``: whether the bound
warning was given), so it is checkpointed and rolled back with the frame. Within a
frame it keeps a copy of the field and the poses from before its mapping call, to undo
the call when the frame fails half way (:meth:`KeyframeBackEnd.rollback`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import torch

from eslam.data.depth_units import DepthCheck
from eslam.errors import InputError
from eslam.field.scene_field import SceneField
from eslam.registry import Registry
from eslam.slam.context import RunContext
from eslam.slam.cuda_graphs import WindowMapper
from eslam.slam.loops.closer import LoopCloser
from eslam.slam.mapping.bounds_policy import (
    bound_from_frame,
    check_depth_found,
    check_some_depth,
    cover_keyframe,
)
from eslam.slam.mapping.carry import carried_poses, corrections
from eslam.slam.mapping.colour_motion import colour_at_depth_time, moves_colour
from eslam.slam.mapping.keyframe_views import KeyframeViews
from eslam.slam.mapping.keyframes import KeyframeSchedule
from eslam.slam.mapping.mapper import (
    MappingResult,
    MappingSchedule,
    MappingSettings,
    mapping_schedule,
)
from eslam.slam.mapping.passes import KeyframePasses
from eslam.slam.run.observers import MappingDone, MappingStep
from eslam.slam.state import FrameMark, SLAMState, new_field
from eslam.slam.tracking.frontend import TrackedFrame
from eslam.slam.tracking.keyframe_offset import MAPPED
from eslam.slam.views import View
from eslam.types import Frame


@dataclass(frozen=True, eq=False)
class MappingJob:
    """One mapping call, ready to run (:meth:`KeyframeBackEnd.prepare`).

    Attributes:
        index: the frame made a keyframe.
        keyframe: its id in the keyframe store.
        frame: the frame itself.
        window: the frame indices of the window's keyframes (the new one included).
        views: the window's keyframes as Views.
        poses: (W, 4, 4) their poses when the call was prepared, on the run's device.
        optimise: per window keyframe, whether its pose is refined (the oldest is held).
        schedule: iterations, rates, rays (the first call's for the map's first keyframe).
        first: the map's first keyframe.
    """

    index: int
    keyframe: int
    frame: Frame
    window: tuple[int, ...]
    views: list[View]
    poses: torch.Tensor
    optimise: list[bool]
    schedule: MappingSchedule
    first: bool


class BackEnd(Protocol):
    """Builds and refines the map in ``state`` from tracked frames (module doc)."""

    def begin_frame(self) -> None:
        """A frame starts (forget what the last frame's :meth:`rollback` would undo)."""
        ...

    def add(
        self, frame: Frame, index: int, tracked: TrackedFrame, state: SLAMState, total: int | None
    ) -> bool:
        """Frame ``index`` (``total`` in the run, None if unknown), tracked as ``tracked``
        and already appended to ``state``'s trajectory: map it if it is a keyframe.
        Returns whether it was mapped."""
        ...

    def finish(self, state: SLAMState, last: Frame | None) -> None:
        """The stream ended with ``last`` (frame ``state.next_frame - 1``): map what is
        left to map."""
        ...

    def settle(self, state: SLAMState) -> None:
        """The run stops (the stream ended, or it was stopped): finish the mapping work
        under way, so that a checkpoint holds whole mapping calls. Optional: the loop
        skips a back end without it (one that maps in turn, written before it existed)."""
        ...

    def rollback(self, state: SLAMState, mark: FrameMark) -> None:
        """Undo the frame begun at ``mark`` (its mapping call included)."""
        ...

    def close(self) -> None:
        """The run is over, however it ended: release what the back end holds (a worker
        beside the tracker). Optional, as :meth:`settle` is."""
        ...


class KeyframeBackEnd:
    """The paper's back end (module doc)."""

    def __init__(self, context: RunContext) -> None:
        config = context.config
        self.context = context
        self.schedule = KeyframeSchedule(config.mapping.every)
        self.mapping = MappingSettings(config.mapping, config.render, config.loss)
        self.mapper = WindowMapper(self.mapping, config.compute.cuda_graphs)
        self.views: KeyframeViews | None = None
        # no scene bound: one set too small is grown (or, growth off, warned about), a
        # matter of the bound and not of depth units
        self.depth_check = DepthCheck.for_run(
            config.data.depth_scale, bound=None, enabled=config.data.depth_check
        )
        self._before: tuple[dict[str, torch.Tensor], torch.Tensor] | None = None
        self.passes = KeyframePasses(context, self.mapper, self._views)
        self.loops = (
            LoopCloser(context, self.passes.follow_correction)
            if config.mapping.loops.enabled
            else None
        )

    def begin_frame(self) -> None:
        self._before = None

    def add(
        self, frame: Frame, index: int, tracked: TrackedFrame, state: SLAMState, total: int | None
    ) -> bool:
        if not tracked.has_depth:
            check_some_depth(index, total, len(state.keyframes), self.context.source)
        if state.field is None:
            self._create_field(frame, index, tracked.has_depth, state)
        mapped = self.wants_keyframe(index, tracked, len(state.keyframes))
        if mapped:
            self.map_frame(frame, index, state)
        state.last_mapped = mapped or tracked.failed or not tracked.has_depth
        return mapped

    def wants_keyframe(self, index: int, tracked: TrackedFrame, known: int) -> bool:
        """Whether frame ``index`` becomes a keyframe (``known`` exist or are queued): a
        tracked frame the schedule makes one, one the front end recovered, or one
        reaching new space."""
        return not tracked.failed and (
            tracked.recovered
            or self.schedule.is_keyframe(index, tracked.has_depth, known)
            or self.new_space(tracked)
        )

    def new_space(self, tracked: TrackedFrame) -> bool:
        """Whether less than ``mapping.keyframe_coverage`` of the tracked frame lay in
        observed space (the front end measures it with ``tracking.observed_only``)."""
        coverage = self.context.config.mapping.keyframe_coverage
        share = tracked.kept.get("observed")
        return tracked.tracked and share is not None and share < coverage

    def settle(self, state: SLAMState) -> None:
        """Nothing is under way between frames: every call ran in turn."""

    def finish(self, state: SLAMState, last: Frame | None) -> None:
        self._map_last(state, last)
        if self.loops is not None:
            self.loops.refine(state, lambda s, passes: self.passes.run(s, passes, True))

    def _map_last(self, state: SLAMState, last: Frame | None) -> None:
        if state.last_mapped:
            return
        if last is None:
            raise InputError(
                Path(self.context.source),
                "the last frame of the stream must be mapped, but it is no longer available",
                "start the run again",
            )
        self.map_frame(last, state.next_frame - 1, state)
        state.last_mapped = True

    def rollback(self, state: SLAMState, mark: FrameMark) -> None:
        field_before = None
        if self._before is not None:
            field_state, poses = self._before
            config = self.context.config.field
            field_before = SceneField.from_state(config, field_state).to(self.context.device)
            state.trajectory.set_poses(list(range(len(poses))), poses)
        state.rollback(mark, field_before)
        if self.views is not None:
            self.views.forget_from(mark.keyframes)
        self._before = None

    def _create_field(self, frame: Frame, index: int, has_depth: bool, state: SLAMState) -> None:
        """Build the field from the first frame with depth, seen from frame 0's pose
        (every frame before it had none: the field is built from the first that has)."""
        if not has_depth:
            check_depth_found(index + 1, self.context.source)
            return
        first = state.trajectory.poses[0]
        bound = bound_from_frame(self.context.config.scene, frame, first, self.context.logger)
        state.field = new_field(self.context.config, bound, self.context.device)

    def _views(self, state: SLAMState) -> KeyframeViews:
        if self.views is None:
            cache_mb = self.context.config.mapping.view_cache_mb
            directions = self.context.directions
            self.views = KeyframeViews(state.keyframes, directions, self.context.device, cache_mb)
        return self.views

    def map_frame(self, frame: Frame, index: int, state: SLAMState) -> None:
        """Make frame ``index`` a keyframe and run one mapping call on its window."""
        field = state.field
        if field is None:
            raise RuntimeError("mapping before the field exists")
        self._before = (
            {k: v.detach().clone() for k, v in field.state_dict().items()},
            state.trajectory.poses.clone(),
        )
        job = self.prepare(frame, index, state, field)
        observers = self.context.observers

        def progress(done: int) -> None:
            observers.on_mapping_step(MappingStep(index, done, job.schedule.iterations, job.first))

        progress(0)
        result = self.mapper.map(
            field,
            job.views,
            job.poses,
            job.optimise,
            job.schedule,
            generator=state.generator,
            on_step=progress,
        )
        self.apply(job, result, state)

    def prepare(self, frame: Frame, index: int, state: SLAMState, field: SceneField) -> MappingJob:
        """Make frame ``index`` a keyframe: check its depth, add it to the store, grow
        ``field``'s bound to hold it, choose its window; return the mapping call to run."""
        config, source = self.context.config, self.context.source
        # a wrong depth unit mid-stream (a live source, a mixed folder) must not be mapped
        self.depth_check.check(frame.depth, source, f"frame {index} (a keyframe)")
        store = state.keyframes
        if moves_colour(config.mapping.colour_motion, self.context.real_time):
            frame = colour_at_depth_time(frame, state.trajectory, index)
        current = store.add(frame, index)
        own = state.component("back_end")
        own["bound_warned"] = cover_keyframe(
            field,
            store.depth(current, self.context.device),
            store.intrinsics,
            state.trajectory.poses[index],
            config.scene,
            state.generator,
            bool(own.get("bound_warned", False)),
            self.context.logger,
        )
        window = state.window.select(store, current, state.generator)
        frame_of = store.frame_indices
        oldest = min(window, key=lambda k: frame_of[k])
        first = len(store) == 1
        return MappingJob(
            index=index,
            keyframe=current,
            frame=frame,
            window=tuple(frame_of[k] for k in window),
            views=self._views(state).views(window),
            poses=store.poses[window].to(self.context.device),
            optimise=[config.mapping.optimise_poses and k != oldest for k in window],
            schedule=mapping_schedule(config.mapping, first, self.context.real_time),
            first=first,
        )

    def apply(self, job: MappingJob, result: MappingResult, state: SLAMState) -> None:
        """The mapping call ``job`` returned ``result``: its refined poses go to the
        trajectory, the observers hear of it, loop closure looks at the new keyframe."""
        moved = [i for i, flag in enumerate(job.optimise) if flag]
        if moved:
            frames = [job.window[i] for i in moved]
            before = state.trajectory.poses[frames]
            state.trajectory.set_poses(frames, result.poses[moved])
            if self.context.config.mapping.carry_frames:
                self._carry(state, frames, before)
        state.component("back_end")[MAPPED] = job.index  # the front end's keyframe offset
        self.context.observers.on_mapping(
            MappingDone(job.index, job.window, job.schedule.iterations, result.loss)
        )
        if self.loops is not None:
            self.loops.after_keyframe(job.index, job.keyframe, state)

    def _carry(self, state: SLAMState, frames: list[int], before: torch.Tensor) -> None:
        """The frames between keyframes follow the keyframes ``frames`` that the call
        moved from ``before`` (``mapping.carry_frames``, :mod:`eslam.slam.mapping.carry`)."""
        trajectory = state.trajectory
        poses = trajectory.poses.double()
        change = corrections(before.double(), poses[frames])
        carried, poses = carried_poses(
            poses, state.keyframes.frame_indices, dict(zip(frames, change, strict=True))
        )
        if carried:
            trajectory.set_poses(carried, poses)


BACK_ENDS: Registry[BackEnd] = Registry("mapping back end", "mapping.back_end")
"""Mapping back ends by ``mapping.back_end``; a factory takes the run's :class:`RunContext`."""


def keyframe_back_end(context: RunContext) -> BackEnd:
    """The paper's back end, its calls beside the tracker with ``concurrent_mapping``
    (:mod:`eslam.slam.mapping.concurrent_mapping`)."""
    if context.concurrent_mapping:
        from eslam.slam.mapping.concurrent_mapping import ConcurrentBackEnd

        return ConcurrentBackEnd(context)
    return KeyframeBackEnd(context)


BACK_ENDS.register("keyframes", keyframe_back_end)


def make_back_end(context: RunContext) -> BackEnd:
    """The back end ``mapping.back_end`` names, built for ``context``."""
    return BACK_ENDS.make(context.config.mapping.back_end, context)
