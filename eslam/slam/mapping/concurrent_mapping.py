"""Mapping beside tracking (``mapping.concurrent``): the back end's calls in a worker.

:class:`ConcurrentBackEnd` chooses keyframes as :class:`~eslam.slam.mapping.backend.
KeyframeBackEnd` does, but hands each mapping call to a worker while the run loop goes on
tracking: a process of its own on a CPU, a thread (on a GPU, on a CUDA stream of its
own) elsewhere (``mapping.concurrent_worker``, :mod:`eslam.slam.mapping.workers`). What
the run loop and the worker touch is owned by one of them at a time and handed over
explicitly:

- The tracker reads ``state.field``: the map as of the last *completed* call. The worker
  maps a field of its own (the working field). When a call completes, the run loop's
  thread (between two frames, so never while the tracker reads) copies the working field
  into ``state.field`` whole (in place, or a new field when the call grew the bound),
  writes the call's refined keyframe poses to the trajectory and tells the observers.
- The run loop's thread prepares each call while the worker is idle (the keyframe added
  to the store, the bound grown, the window chosen, its views built:
  :meth:`~eslam.slam.mapping.backend.KeyframeBackEnd.prepare`) and hands it over; the
  worker gives back the result, or its error, through a future.
- One call runs at a time. A keyframe that comes while one runs waits. When another
  comes while one waits: in real time the newer replaces the waiting one (the mapper
  cannot keep up, and the newest view matters most; replacements are counted and log.txt
  says when the first happens); on recorded data the tracker waits for the mapper, so
  every keyframe is mapped and the tracker is at most two keyframes ahead of the map.

The map's first keyframe: its TSDF warm start (``mapping.first_warm_start: tsdf``) runs
before the hand-over (its first ``mapping.first_warm_start_lead`` steps only, when that
is set: the worker runs the others, and the tracker gets the map they leave before the
rendering steps start) and the warm-started map goes to the tracker at once, so
tracking starts while the first call's rendering steps go on; without a warm
start the tracker waits for the first call (there is no map to track on before it).
In real time a later call may begin with TSDF steps over its window
(``mapping.realtime_warm_start``): the worker runs them as a part of their own, whose
map goes to the tracker before the call's rendering steps run (one call counted).

A call is never cut half way: at the end of the stream, when the run stops
(:meth:`ConcurrentBackEnd.settle`) and when a frame fails (:meth:`~ConcurrentBackEnd.
rollback`) the call in flight is waited for, so a checkpoint holds whole calls only (and
at the end of the stream or a stop, the waiting keyframe mapped too; in real time the
stream's last frame takes its place when that frame is not mapped yet). Calls, their busy
time, replacements and the longest queue are kept in ``components["concurrent_mapping"]``
and reported in metrics.json (:func:`concurrency_metrics`). The worker starts with the
first call and lasts until the run is over (:meth:`ConcurrentBackEnd.close`, which the
run loop calls however the run ended), so the last frame's call at the end of the
stream reuses it.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from concurrent.futures import Future
from dataclasses import dataclass

import torch

from eslam.field.scene_field import SceneField
from eslam.slam.context import RunContext
from eslam.slam.mapping.backend import KeyframeBackEnd, MappingJob
from eslam.slam.mapping.bounds_policy import check_some_depth
from eslam.slam.mapping.mapper import MappingResult, MappingSchedule, warm_start_window
from eslam.slam.mapping.workers import MappingCall, Worker, make_worker, worker_kind
from eslam.slam.state import FrameMark, SLAMState
from eslam.slam.tracking.frontend import TrackedFrame
from eslam.types import Frame

COMPONENT = "concurrent_mapping"
"""The back end's counts in ``state.components``: calls, busy_s, replaced, queue (after
the last frame: in flight plus waiting), queue_max."""

_GRID_KEYS = ("bound", "vertices", "window")
"""Field entries that fix its layout: equal in both fields, the copy can be in place."""


@dataclass(frozen=True, eq=False)
class Flight:
    """A mapping call handed to the worker.

    Attributes:
        job: the call.
        future: its result.
        handed_at: the frame being processed when it was handed over.
        started: when (seconds, ``time.perf_counter``).
        then: the rest of the call, handed over once this part is done and in the
            tracker's map (the rendering steps, after the warm-start steps the worker
            runs: the first keyframe's, a later call's in real time), or None.
    """

    job: MappingJob
    future: Future[MappingResult]
    handed_at: int
    started: float
    then: MappingSchedule | None = None


def split_warm_start(
    schedule: MappingSchedule, lead: int | None
) -> tuple[MappingSchedule, MappingSchedule]:
    """The first call's ``schedule`` (with a warm start) as what runs before the tracker
    gets the map (its warm start's first ``lead`` steps; None: all) and what the worker
    runs (the other steps, then the rendering steps)."""
    warm = schedule.warm_start
    if warm is None:
        raise ValueError("split_warm_start needs a schedule with a warm start")
    steps = warm.steps if lead is None else min(lead, warm.steps)
    rest = warm.steps - steps
    before = dataclasses.replace(schedule, warm_start=dataclasses.replace(warm, steps=steps))
    after = dataclasses.replace(
        schedule, warm_start=dataclasses.replace(warm, steps=rest) if rest > 0 else None
    )
    return before, after


def same_layout(a: SceneField, b: SceneField) -> bool:
    """Whether fields ``a`` and ``b`` have the same bound and plane grids (so one's
    values can be copied into the other's tensors)."""
    left, right = a.state_dict(), b.state_dict()
    if left.keys() != right.keys():
        return False
    for key, value in left.items():
        if value.shape != right[key].shape:
            return False
        if key.endswith(_GRID_KEYS) and not torch.equal(value, right[key]):
            return False
    return True


def copy_field(source: SceneField, target: SceneField | None) -> SceneField:
    """``source``'s values in ``target`` (copied in place when the layouts agree, so
    whoever holds ``target`` sees the new map), else in a copy of ``source``."""
    if target is None or not same_layout(source, target):
        return copy.deepcopy(source)
    with torch.no_grad():
        values = source.state_dict()
        for key, tensor in target.state_dict().items():
            tensor.copy_(values[key])
    return target


class ConcurrentBackEnd(KeyframeBackEnd):
    """The keyframe back end with its mapping calls beside the tracker (module doc)."""

    def __init__(self, context: RunContext) -> None:
        super().__init__(context)
        if self.loops is not None:
            raise ValueError("concurrent mapping does not close loops")  # the config refuses it
        self.worker_kind = worker_kind(context.config.mapping.concurrent_worker, context.device)
        self.worker: Worker | None = None  # made at the first call, with the mapper then
        self.generator = torch.Generator(device=context.device)
        self.generator.manual_seed(context.config.seed + 1)  # the worker's own draws
        self.working: SceneField | None = None
        self.flight: Flight | None = None
        self.waiting: tuple[Frame, int] | None = None
        self._frame = -1

    def add(
        self, frame: Frame, index: int, tracked: TrackedFrame, state: SLAMState, total: int | None
    ) -> bool:
        """Frame ``index``: a completed call is taken in, a keyframe queued, the next call
        handed over when the worker is idle. Returns whether the frame became a keyframe
        (queued for the mapper, not yet mapped)."""
        self._frame = index
        state.component(COMPONENT)  # metrics.json reports the counts, zero or not
        self.collect(state, wait=False)
        if not tracked.has_depth:
            check_some_depth(index, total, len(state.keyframes), self.context.source)
        if state.field is None:
            self._create_field(frame, index, tracked.has_depth, state)
        known = len(state.keyframes) + (self.waiting is not None)
        keyframe = self.wants_keyframe(index, tracked, known)
        if keyframe:
            self._queue(frame, index, state)
        state.last_mapped = tracked.failed or not tracked.has_depth
        self._hand_over(state)
        own = state.component(COMPONENT)
        own["queue"] = (self.flight is not None) + (self.waiting is not None)
        return keyframe

    def _queue(self, frame: Frame, index: int, state: SLAMState) -> None:
        own = state.component(COMPONENT)
        if self.waiting is not None and not self.context.real_time:
            # recorded data: every keyframe is mapped, the tracker waits for the mapper
            self.collect(state, wait=True)
            self._hand_over(state)
        if self.waiting is not None:
            self._replace(state, index)
        self.waiting = (frame, index)
        own["queue_max"] = max(own.get("queue_max", 0), 1 + (self.flight is not None))

    def _replace(self, state: SLAMState, index: int) -> None:
        """The waiting keyframe gives way to frame ``index`` (counted; the first said)."""
        assert self.waiting is not None
        own = state.component(COMPONENT)
        own["replaced"] = own.get("replaced", 0) + 1
        if own["replaced"] == 1:
            self.context.logger.warning(
                "mapping falls behind: keyframe %d replaced by frame %d while frame %d "
                "is mapped (only the newest waiting keyframe is kept)",
                self.waiting[1],
                index,
                -1 if self.flight is None else self.flight.job.index,
            )
        self.waiting = None

    def _hand_over(self, state: SLAMState) -> None:
        """Give the waiting keyframe's call to the worker if it is idle."""
        if self.flight is not None or self.waiting is None or state.field is None:
            return
        frame, index = self.waiting
        self.waiting = None
        if self.working is None:
            self.working = copy.deepcopy(state.field)
        working = self.working
        job = self.prepare(frame, index, state, working)
        warmed = job.schedule.warm_start is not None
        then = None
        if warmed:
            # the first keyframe's lead steps run here (the tracker has that map at once);
            # a later call's (in real time) all run in the worker
            lead = self.mapping.mapping.first_warm_start_lead if job.first else 0
            before, rest = split_warm_start(job.schedule, lead)
            if job.first:
                views, poses = job.views, job.poses
                warm_start_window(working, views, poses, self.mapping, before, self.generator)
                self._publish(state)
            if rest.warm_start is not None:  # the worker's warm-start steps reach the
                then = dataclasses.replace(rest, warm_start=None)  # tracker before the
                rest = dataclasses.replace(rest, iterations=0)  # rendering steps run
            job = dataclasses.replace(job, schedule=rest)
        self._submit(job, state, self._frame, time.perf_counter(), then)
        if index == state.next_frame - 1:
            state.last_mapped = True
        if job.first and not warmed:
            self.collect(state, wait=True)  # no warm start: no map to track on before it

    def _submit(
        self,
        job: MappingJob,
        state: SLAMState,
        handed_at: int,
        started: float,
        then: MappingSchedule | None = None,
    ) -> None:
        """Hand ``job`` to the worker (made at the first call) on the working field."""
        assert self.working is not None
        call = MappingCall(self.working, job.views, job.poses, job.optimise, job.schedule)
        if self.worker is None:
            self.worker = make_worker(self.worker_kind, self.mapper, self.context.device)
            state.component(COMPONENT)["worker"] = self.worker.kind
            self.context.logger.info("mapping beside the tracker in a %s", self.worker.kind)
        future = self.worker.submit(call, self.generator)
        self.flight = Flight(job, future, handed_at, started, then)

    def _publish(self, state: SLAMState) -> None:
        """The working field becomes the tracker's map (between frames)."""
        assert self.working is not None
        state.field = copy_field(self.working, state.field)

    def collect(self, state: SLAMState, wait: bool) -> None:
        """Take in the call in flight if it is done (``wait``: once it is): the tracker
        gets its map, the trajectory its poses. A call that failed is dropped (its
        keyframe with it) and its error raised; Ctrl-C while waiting leaves it in flight."""
        flight = self.flight
        if flight is None or not (wait or flight.future.done()):
            return
        try:
            result = flight.future.result()
        except BaseException:
            if not flight.future.done():  # interrupted while waiting: the call goes on
                raise
            self.flight = None
            self._drop(state, flight.job)
            raise
        self.flight = None
        self._publish(state)
        if flight.then is not None:  # the first part is in the tracker's map: the rest
            rest = dataclasses.replace(flight.job, schedule=flight.then)
            self._submit(rest, state, flight.handed_at, flight.started)
            self.collect(state, wait)
            return
        own = state.component(COMPONENT)
        own["calls"] = own.get("calls", 0) + 1
        own["busy_s"] = own.get("busy_s", 0.0) + time.perf_counter() - flight.started
        self.apply(flight.job, result, state)

    def _drop(self, state: SLAMState, job: MappingJob) -> None:
        """Forget a call whose result is not taken in: its keyframe leaves the store, the
        working field (changed by it) is copied from the tracker's map again."""
        self.working = None
        state.keyframes.truncate(job.keyframe)
        if self.views is not None:
            self.views.forget_from(job.keyframe)

    def settle(self, state: SLAMState) -> None:
        """Wait for the call in flight and map the waiting keyframe (the run stops here).
        In real time, when the stream's newest frame is not mapped yet, it takes the
        waiting keyframe's place (:meth:`finish` maps it), as a newer keyframe would."""
        self.collect(state, wait=True)
        newest = state.next_frame - 1
        if self.waiting is not None and self.context.real_time and not state.last_mapped:
            if self.waiting[1] == newest:
                self.waiting = None  # finish maps it, as the stream's last frame
            else:
                self._replace(state, newest)
        self._drain(state)

    def _drain(self, state: SLAMState) -> None:
        """Wait for the call in flight, then map the waiting keyframe."""
        self.collect(state, wait=True)
        if self.waiting is not None:
            self._hand_over(state)
            self.collect(state, wait=True)

    def finish(self, state: SLAMState, last: Frame | None) -> None:
        self._drain(state)
        if not state.last_mapped and last is not None:
            self.waiting = (last, state.next_frame - 1)
            self._drain(state)
        self._map_last(state, last)  # only a last frame no longer available is left

    def close(self) -> None:
        """The run is over: the worker ends (a call in flight finishes first)."""
        if self.worker is not None:
            self.worker.close()

    def rollback(self, state: SLAMState, mark: FrameMark) -> None:
        """Undo the frame begun at ``mark``: the call in flight is waited for and taken in
        when a completed frame handed it over, dropped when this frame did (its keyframe
        waits again if it came from a completed frame)."""
        flight = self.flight
        try:
            if flight is not None:
                flight.future.exception()  # wait, whatever its outcome
                if flight.handed_at < mark.frames:
                    try:
                        self.collect(state, wait=True)
                    except Exception:  # dropped with its keyframe; the frame's error is raised
                        pass
                else:
                    self.flight = None
                    self._drop(state, flight.job)
                    if flight.job.index < mark.frames:
                        self.waiting = (flight.job.frame, flight.job.index)
        finally:  # the frame is undone even when a second Ctrl-C cuts the wait short
            if self.waiting is not None and self.waiting[1] >= mark.frames:
                self.waiting = None
            counts = dict(state.component(COMPONENT))  # calls taken in above stay counted
            state.rollback(mark, None)
            state.components[COMPONENT] = counts
            if self.views is not None:
                self.views.forget_from(mark.keyframes)


def concurrency_metrics(state: SLAMState, wall_s: float) -> dict:
    """metrics.json's keys of a concurrent run over ``wall_s`` seconds (none for a run
    that maps in turn): mapping calls completed, their rate, the share of the run the
    mapper was busy, keyframes replaced while waiting, the longest queue (in flight
    plus waiting)."""
    own = state.components.get(COMPONENT)
    if own is None:
        return {}
    calls = int(own.get("calls", 0))
    busy = float(own.get("busy_s", 0.0))
    return {
        "mapping_concurrent": True,
        "mapping_worker": own.get("worker"),
        "mapping_calls": calls,
        "mapping_calls_per_s": calls / wall_s if wall_s > 0 else 0.0,
        "mapping_busy_share": busy / wall_s if wall_s > 0 else 0.0,
        "mapping_keyframes_replaced": int(own.get("replaced", 0)),
        "mapping_queue_max": int(own.get("queue_max", 0)),
    }
