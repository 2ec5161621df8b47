"""The observer seam: what the run loop tells the world, and the protocol to listen.

The loop calls every observer at the run's start, after each frame, at the start and
after each iteration of a mapping call, after each mapping call, at the finish and on a
failure; observers never change the run. The run writer
(:mod:`eslam.slam.run.writer`), the progress bar (:mod:`eslam.slam.run.progress`) and the
log lines (:class:`LogObserver`) are observers; a viewer or a live trajectory stream are
more of them, passed to :func:`eslam.slam.session.run_slam` as ``observers=``.

Events carry device tensors as they are (no copies, no host syncs): an observer that
needs numbers on the host pays for the transfer itself.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import torch

from eslam.config import ESLAMConfig
from eslam.slam.tracking.base import TrackingQuality
from eslam.types import Frame

if TYPE_CHECKING:
    from eslam.slam.state import SLAMState


@dataclass(frozen=True, eq=False)
class RunStart:
    """A run begins (or resumes).

    Attributes:
        config: the run's configuration.
        run_dir: the run folder.
        state: the run's state (read it, never change it).
        device: the compute device.
        source: the frame source's name.
        frames: frames the source will yield, None when unknown (a live stream).
        resumed: whether the run continues from a checkpoint.
    """

    config: ESLAMConfig
    run_dir: Path
    state: SLAMState
    device: torch.device
    source: str
    frames: int | None
    resumed: bool


@dataclass(frozen=True, eq=False)
class FrameDone:
    """A frame was tracked (and, if it is a keyframe, mapped).

    Attributes:
        index: the frame's index in the run.
        pose: (4, 4) its pose estimate on the device (before later refinement).
        tracked: whether the tracker ran (False for frame 0, frames without depth and
            frames before the first keyframe: they keep the motion model's pose).
        quality: the tracker's judgement (None when it has none or did not run); a
            failed frame keeps the motion model's pose and is no keyframe.
        mapped: whether the frame became a keyframe and was mapped.
        tracking_s / mapping_s: wall time of each part, seconds (device work included).
        frame: the input frame itself (host images, camera, ground truth), for observers
            that show it (a viewer); None where a sender has none to give.
        has_depth: whether the frame had any valid depth (none: not tracked or mapped).
        emptied_by: why a view filter left the frame no pixel to track on, in the
            filter's words (it kept the motion model's pose), else None.
    """

    index: int
    pose: torch.Tensor
    tracked: bool
    quality: TrackingQuality | None
    mapped: bool
    tracking_s: float
    mapping_s: float
    frame: Frame | None = None
    has_depth: bool = True
    emptied_by: str | None = None

    @property
    def failed(self) -> bool:
        """Whether the tracker judged the frame failed."""
        return self.quality is not None and self.quality.failed


@dataclass(frozen=True, eq=False)
class MappingDone:
    """A mapping call finished.

    Attributes:
        index: the frame mapped.
        window: the frame indices of the window's keyframes.
        iterations: optimisation steps taken.
        loss: 0-d tensor on the device, the loss of the last step.
    """

    index: int
    window: tuple[int, ...]
    iterations: int
    loss: torch.Tensor


@dataclass(frozen=True)
class MappingStep:
    """Progress of a mapping call: sent before its first iteration (``done`` = 0) and
    after each one, so a long call (the first frame's: 1000 iterations in the paper,
    minutes on a CPU) is visibly alive. Counts only: no loss, so no host sync.

    Attributes:
        index: the frame being mapped.
        done: iterations finished so far.
        iterations: iterations of the call.
        first: the map's first call (the empty map: the long one).
    """

    index: int
    done: int
    iterations: int
    first: bool


@dataclass(frozen=True, eq=False)
class RunEnd:
    """The run stopped: the stream ended (``complete``) or it was stopped early.

    Attributes:
        complete: the stream ended (the last frame was mapped); False after
            ``stop_after`` frames.
        frames: frames processed in all (including before a resume).
        wall_s: wall time of this process's part of the run, seconds.
        interrupted: Ctrl-C ended a live or real-time stream (it then counts as complete).
    """

    complete: bool
    frames: int
    wall_s: float
    interrupted: bool = False


class RunObserver(Protocol):
    """Listens to a run; every method is optional in spirit (implement it as a no-op)."""

    def on_start(self, start: RunStart) -> None:
        """Before the first frame."""
        ...

    def on_frame(self, frame: FrameDone) -> None:
        """After each frame."""
        ...

    def on_mapping_step(self, step: MappingStep) -> None:
        """At the start and after each iteration of a mapping call (keep it cheap)."""
        ...

    def on_mapping(self, mapping: MappingDone) -> None:
        """After each mapping call."""
        ...

    def on_finish(self, end: RunEnd) -> None:
        """After the last frame (and the final mapping call)."""
        ...

    def on_failure(self, error: BaseException, frames: int) -> None:
        """The run stopped on ``error``; the state holds the ``frames`` completed frames."""
        ...


class RunObserverBase:
    """No-op implementations of every :class:`RunObserver` method, to inherit from."""

    def on_start(self, start: RunStart) -> None:
        """Before the first frame."""

    def on_frame(self, frame: FrameDone) -> None:
        """After each frame."""

    def on_mapping_step(self, step: MappingStep) -> None:
        """At the start and after each iteration of a mapping call."""

    def on_mapping(self, mapping: MappingDone) -> None:
        """After each mapping call."""

    def on_finish(self, end: RunEnd) -> None:
        """After the last frame."""

    def on_failure(self, error: BaseException, frames: int) -> None:
        """The run stopped on ``error``."""


class Observers(RunObserverBase):
    """Several observers called in order, as one."""

    def __init__(self, observers: Sequence[RunObserver]) -> None:
        self.observers = list(observers)

    def on_start(self, start: RunStart) -> None:
        for observer in self.observers:
            observer.on_start(start)

    def on_frame(self, frame: FrameDone) -> None:
        for observer in self.observers:
            observer.on_frame(frame)

    def on_mapping_step(self, step: MappingStep) -> None:
        """Tell the observers that listen (an observer written before this event, without
        the method, is skipped)."""
        for observer in self.observers:
            listen = getattr(observer, "on_mapping_step", None)
            if listen is not None:
                listen(step)

    def on_mapping(self, mapping: MappingDone) -> None:
        for observer in self.observers:
            observer.on_mapping(mapping)

    def on_finish(self, end: RunEnd) -> None:
        for observer in self.observers:
            observer.on_finish(end)

    def on_failure(self, error: BaseException, frames: int) -> None:
        """Tell every observer, even when one of them fails (the first failure is raised)."""
        failure: BaseException | None = None
        for observer in self.observers:
            try:
                observer.on_failure(error, frames)
            except Exception as nested:
                failure = failure or nested
        if failure is not None:
            raise failure


class LogObserver(RunObserverBase):
    """The run's own log lines (start, mapping calls, end, failure) on the run's logger
    (:func:`eslam.slam.session.run_log`: log.txt at INFO, whatever level "eslam" has)."""

    def __init__(self, logger: logging.Logger) -> None:
        self.log = logger

    def on_start(self, start: RunStart) -> None:
        if start.resumed:
            self.log.info("resuming %s at frame %d", start.source, start.state.next_frame)
        else:
            frames = "unknown number of" if start.frames is None else str(start.frames)
            self.log.info("run on %s: %s frames, device %s", start.source, frames, start.device)

    def on_mapping(self, mapping: MappingDone) -> None:
        self.log.info(
            "mapped frame %d: window %s, loss %.5f",
            mapping.index,
            list(mapping.window),
            float(mapping.loss),
        )

    def on_finish(self, end: RunEnd) -> None:
        state = "finished" if end.complete else "stopped"
        how = " (the stream was ended by Ctrl-C or SIGTERM)" if end.interrupted else ""
        self.log.info("run %s after %d frames (%.1f s)%s", state, end.frames, end.wall_s, how)

    def on_failure(self, error: BaseException, frames: int) -> None:
        self.log.error("run stopped after %d completed frames: %s", frames, _describe(error))


def _describe(error: BaseException) -> str:
    text = str(error)
    return type(error).__name__ if not text else f"{type(error).__name__}: {text}"
