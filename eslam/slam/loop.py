"""The run loop: a sequencer of frames through a front end and a back end (ARCHITECTURE.md).

For each frame, :class:`RunLoop` asks the tracking front end
(:mod:`eslam.slam.tracking.frontend`) for its pose, appends it to the trajectory, and hands the
frame to the mapping back end (:mod:`eslam.slam.mapping.backend`), which maps it if it is a
keyframe; when the stream ends, the back end maps what is left. Everything the world
sees goes through observers (:mod:`eslam.slam.run.observers`). Wiring a run (config, input,
run folder, components) is :mod:`eslam.slam.session`'s.

A frame that fails half way (unreadable file, out of memory, Ctrl-C) is rolled back,
so the state holds exactly the completed frames.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator

from eslam.data.prefetch import close_iterator
from eslam.slam.mapping.backend import BackEnd
from eslam.slam.run.observers import FrameDone, RunEnd, RunObserver
from eslam.slam.run.resources import device_clock
from eslam.slam.state import FrameMark, SLAMState, quality_row
from eslam.slam.tracking.frontend import FrontEnd
from eslam.types import Frame

__all__ = ["RunLoop"]


class RunLoop:
    """Processes frames one at a time against a run's state (module doc).

    Args:
        state: the state to advance (fresh or resumed).
        front_end: estimates each frame's pose.
        back_end: builds and refines the map.
        observers: told about every frame (the back end tells them about mapping).
        end_on_interrupt: Ctrl-C (or SIGTERM) ends the stream as its end would: the frame
            in progress is rolled back, the last frame mapped, the run finished (a live
            or real-time run has no other way to end).
    """

    def __init__(
        self,
        state: SLAMState,
        front_end: FrontEnd,
        back_end: BackEnd,
        observers: RunObserver,
        end_on_interrupt: bool = False,
    ) -> None:
        self.state = state
        self.front_end = front_end
        self.back_end = back_end
        self.observers = observers
        self.end_on_interrupt = end_on_interrupt
        self.last_frame: Frame | None = None
        self._total: int | None = None

    def run(self, frames: Iterable[Frame], total: int | None, stop_after: int | None) -> RunEnd:
        """Process ``frames`` (``total`` of them in the whole run, None if unknown) until
        they end or ``stop_after`` frames are done; map the last frame at the end.

        On any error the frame in progress is rolled back before the error propagates;
        Ctrl-C with ``end_on_interrupt`` ends the stream instead (class doc).
        """
        try:
            return self._run(frames, total, stop_after)
        finally:
            close = getattr(self.back_end, "close", None)  # optional, as settle is
            if close is not None:
                close()  # a worker beside the tracker ends, however the run ended

    def _run(self, frames: Iterable[Frame], total: int | None, stop_after: int | None) -> RunEnd:
        state = self.state
        self._total = total
        began = time.perf_counter()
        iterator: Iterator[Frame] = iter(frames)
        complete = True
        interrupted = False
        while True:
            if stop_after is not None and state.next_frame >= stop_after:
                complete = total is not None and state.next_frame >= total
                break
            mark = self._mark()
            try:
                frame = next(iterator, None)
                if frame is None:
                    break
                done = self.process(frame)
            except BaseException as error:
                self.back_end.rollback(state, mark)
                if not (self.end_on_interrupt and isinstance(error, KeyboardInterrupt)):
                    raise
                interrupted = True
                break
            try:
                self.observers.on_frame(done)  # the frame is complete: never rolled back
            except KeyboardInterrupt:
                if not self.end_on_interrupt:
                    raise
                interrupted = True
                break
        close_iterator(iterator)  # a reader thread stops taking frames it cannot process
        settle = getattr(self.back_end, "settle", None)  # a back end without it maps in turn
        if settle is not None:
            settle(state)  # mapping under way (beside the tracker) completes
        if complete:
            mark = self._mark()
            try:
                self.finish()
            except BaseException:
                self.back_end.rollback(state, mark)
                raise
        return RunEnd(
            complete=complete,
            frames=state.next_frame,
            wall_s=time.perf_counter() - began,
            interrupted=interrupted,
        )

    def _mark(self) -> FrameMark:
        self.back_end.begin_frame()
        return self.state.mark()

    def process(self, frame: Frame) -> FrameDone:
        """Track ``frame``, map it if it is a keyframe; return what happened."""
        state = self.state
        index = state.next_frame
        device = state.generator.device
        started = device_clock(device)
        tracked = self.front_end.track(frame, index, state)
        state.trajectory.append(tracked.pose, frame.timestamp, frame.pose_gt)
        state.tracking_quality.append(quality_row(tracked.quality))
        done_tracking = device_clock(device)
        mapped = self.back_end.add(frame, index, tracked, state, self._total)
        done = device_clock(device)
        state.tracking_time.append(done_tracking - started)
        state.mapping_time.append(done - done_tracking)
        self.last_frame = frame
        return FrameDone(
            index=index,
            pose=state.trajectory.poses[index],
            tracked=tracked.tracked,
            quality=tracked.quality,
            mapped=mapped,
            tracking_s=done_tracking - started,
            mapping_s=done - done_tracking,
            frame=frame,
            has_depth=tracked.has_depth,
            emptied_by=tracked.emptied_by,
        )

    def finish(self) -> None:
        """At the end of the stream: the back end maps what is left (timed as the last
        frame's mapping)."""
        state = self.state
        if state.last_mapped:
            return
        device = state.generator.device
        started = device_clock(device)
        self.back_end.finish(state, self.last_frame)
        state.mapping_time[-1] += device_clock(device) - started
