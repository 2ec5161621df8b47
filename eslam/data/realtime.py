"""Real-time input (``data.realtime``, ``eslam run --realtime``): the newest frame, never a backlog.

A sensor does not wait for SLAM. :class:`LatestFrameReader` pulls frames from a source
on a thread of its own, as fast as the source gives them, into a one-slot buffer: a
frame that arrives while the run loop is still busy with an earlier one replaces the
waiting frame, which is dropped. The loop always gets the newest frame, the frames it
gets are in stream order (never reordered, each at most once), and the counts add up:
received = handed to the loop + dropped.

A recorded stream replayed in real time emulates its sensor (:class:`ReplayPace`):
frame i is released ``timestamp_i - timestamp_0`` seconds after the first, or
``i / fps`` seconds with ``data.replay_fps`` (recordings whose timestamps are frame
numbers need it: :func:`timestamps_are_frame_numbers`). A camera's frames come decoded,
so a recording that can read any frame on demand is released as :class:`Pending`
frames (their timestamps only) and the loop reads a frame when it takes it: a dropped
frame costs no decoding (decoding fr1/xyz's 30 frames a second takes most of a CPU
core, which a camera would leave to the run). A live source (a camera:
``FrameSource.live``) paces itself.

Errors reading a frame are raised in the loop's thread after the frame waiting before
them, as :mod:`eslam.data.prefetch` does; closing stops the thread the same way.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from eslam.data.prefetch import JOIN_TIMEOUT_S, ReaderThread, close_iterator
from eslam.errors import ConfigError
from eslam.types import Frame

_POLL_S = 0.05
"""How often a waiting thread looks whether it should stop (seconds)."""


def timestamps_are_frame_numbers(timestamps: np.ndarray) -> bool:
    """Whether ``timestamps`` are frame numbers rather than seconds: at least two, all whole
    numbers (readers of layouts without time stamps number the frames: Replica, ScanNet,
    7-Scenes). Seconds from a sensor clock are never all whole at video rates."""
    values = np.asarray(timestamps, dtype=np.float64)
    return len(values) >= 2 and bool(np.all(values == np.round(values)))


def replay_pace_error(name: str) -> ConfigError:
    """The error for replaying ``name`` in real time when its timestamps are frame numbers."""
    return ConfigError(
        f"{name}: its timestamps are frame numbers, not seconds, so it cannot be replayed at "
        "its recorded rate; set the rate with data.replay_fps=FPS (e.g. data.replay_fps=30)"
    )


@dataclass(frozen=True)
class ReplayPace:
    """When a recording's frames are released in a real-time replay.

    Attributes:
        fps: release frame i at i / fps seconds; None: at its timestamp minus the first.
        name: the recording, for the error when its timestamps are frame numbers.
    """

    fps: float | None
    name: str = "the recording"

    def offset_s(self, position: int, timestamp: float, first: float) -> float:
        """Seconds after the first frame's release at which frame ``position`` is released."""
        if self.fps is not None:
            return position / self.fps
        return timestamp - first


@dataclass(frozen=True, eq=False)
class Pending:
    """A recorded frame released in a replay, read when the loop takes it (module doc).

    Attributes:
        timestamp: the frame's timestamp (what the replay is paced by).
        read: reads the frame.
    """

    timestamp: float
    read: Callable[[], Frame]


@dataclass(frozen=True)
class StreamCounts:
    """What a real-time reader saw so far.

    Attributes:
        received: frames the source gave.
        delivered: frames handed to the run loop.
        replaced: frames dropped because a newer one arrived before the loop was ready.
        wall_s: seconds since the first frame arrived (until the reader closed; 0 before).
        arrivals_s: seconds from the first frame's arrival to the last's.
    """

    received: int
    delivered: int
    replaced: int
    wall_s: float
    arrivals_s: float

    @property
    def received_fps(self) -> float:
        """The rate the source gave frames at, (received - 1) / arrivals_s (0 before two)."""
        if self.received < 2 or self.arrivals_s <= 0:
            return 0.0
        return (self.received - 1) / self.arrivals_s


class LatestFrameReader(ReaderThread):
    """The newest frame of ``source`` whenever the loop asks (module doc).

    Use as a context manager; iterate it once inside the ``with`` block.

    Args:
        source: the frames (a live source, or a recording replayed with ``pace``: its
            frames, or :class:`Pending` ones read when the loop takes them).
        pace: how to release a recording's frames; None: as fast as the source gives them
            (a live source paces itself).
        clock: seconds, monotonic (tests pass their own).

    Attributes:
        source_indices: position in the stream (0-based, in arrival order) of every frame
            handed to the loop, in order.
    """

    def __init__(
        self,
        source: Iterable[Frame] | Iterable[Pending],
        pace: ReplayPace | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._source = source
        self._pace = pace
        self._clock = clock
        self._ready = threading.Condition()
        self._stop = threading.Event()
        self._slot: tuple[int, Frame | Pending, float] | None = None
        self._ended = False
        self._failure: BaseException | None = None
        self._received = 0
        self._replaced = 0
        self._first_arrival: float | None = None
        self._last_arrival = 0.0
        self._closed_at: float | None = None
        self.source_indices: list[int] = []
        self._arrivals: list[float] = []  # when each frame handed to the loop arrived
        self.thread = threading.Thread(target=self._read, name="eslam-realtime", daemon=True)

    def _read(self) -> None:
        """The thread: release frames into the slot until the source ends or it must stop."""
        iterator: Iterator[Frame] | Iterator[Pending] | None = None
        try:
            iterator = iter(self._source)
            start: tuple[float, float] | None = None  # (clock, first timestamp)
            for position, frame in enumerate(iterator):
                if self._pace is not None:
                    if start is None:
                        start = (self._clock(), frame.timestamp)
                    elif position == 1 and self._pace.fps is None:
                        self._check_seconds(start[1], frame.timestamp)
                    due = start[0] + self._pace.offset_s(position, frame.timestamp, start[1])
                    if self._stop.wait(max(0.0, due - self._clock())):
                        return
                if self._stop.is_set():
                    return
                self._offer(position, frame)
        except BaseException as error:  # raised in the loop's thread
            with self._ready:
                self._failure = error
                self._ready.notify_all()
        finally:
            with self._ready:
                self._ended = True
                self._ready.notify_all()
            if iterator is not None:
                try:
                    close_iterator(iterator)
                except Exception:  # a failing close must not hide the run's end
                    pass

    def _check_seconds(self, first: float, second: float) -> None:
        if self._pace is not None and timestamps_are_frame_numbers(np.array([first, second])):
            raise replay_pace_error(self._pace.name)

    def _offer(self, position: int, frame: Frame | Pending) -> None:
        with self._ready:
            if self._slot is not None:
                self._replaced += 1
            self._last_arrival = self._clock()
            self._slot = (position, frame, self._last_arrival)
            self._received += 1
            if self._first_arrival is None:
                self._first_arrival = self._last_arrival
            self._ready.notify_all()

    def __iter__(self) -> Iterator[Frame]:
        return self

    def __next__(self) -> Frame:
        with self._ready:
            while self._slot is None and not self._ended and self._failure is None:
                self._ready.wait(_POLL_S)
            if self._slot is not None:
                position, frame, arrival = self._slot
                self._slot = None
                self.source_indices.append(position)
                self._arrivals.append(arrival)
            elif self._failure is not None:
                failure, self._failure = self._failure, None
                raise failure
            else:
                raise StopIteration
        return frame.read() if isinstance(frame, Pending) else frame

    def age_s(self, delivered: int) -> float:
        """Seconds since the ``delivered``-th frame handed to the loop (0-based) arrived:
        called when its pose is done, how far the run lags behind the camera."""
        return self._clock() - self._arrivals[delivered]

    def counts(self) -> StreamCounts:
        """The counts so far (safe to call from any thread)."""
        with self._ready:
            began = self._first_arrival
            now = self._clock() if self._closed_at is None else self._closed_at
            return StreamCounts(
                received=self._received,
                delivered=len(self.source_indices),
                replaced=self._replaced,
                wall_s=0.0 if began is None else now - began,
                arrivals_s=0.0 if began is None else self._last_arrival - began,
            )

    def close(self) -> None:
        """Stop the thread and wait for it (again is fine); a frame still waiting is dropped."""
        self._stop.set()
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(JOIN_TIMEOUT_S)
        with self._ready:
            self._ended = True
            self._slot = None
            if self._closed_at is None:
                self._closed_at = self._clock()
