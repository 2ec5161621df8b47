"""Frames read ahead of the run loop on a background thread (``data.prefetch``).

Reading a frame (decoding two PNGs, undistorting, resizing) is host work the loop
would otherwise wait for between frames. :class:`PrefetchedFrames` iterates a frame
source on a thread of its own and hands the frames over through a bounded queue of
``depth`` frames: the same frames, in the same order, so a run's results do not change.

An error reading a frame (the reader's :class:`~eslam.errors.InputError`, naming the
file) is handed over in the frame's place and raised in the loop's thread when the loop
asks for that frame, after the frames before it. Closing (the ``with`` block's end, however
it ends: the stream's end, ``stop_after``, an error, Ctrl-C) stops the thread: it
finishes the frame it is reading, closes the source's iterator (a camera pipeline stops)
and exits; the closing thread waits for it.
"""

from __future__ import annotations

import queue
import threading
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from types import TracebackType

from eslam.types import Frame

_POLL_S = 0.05
"""How often a blocked thread looks whether it should stop (seconds)."""

JOIN_TIMEOUT_S = 30.0
"""Longest wait for the reader thread to finish its frame when closing (a stuck driver
call cannot hang the run's exit; the thread is a daemon)."""


class _End:
    """The source is exhausted."""


@dataclass(frozen=True)
class _Failure:
    """Reading the next frame raised ``error``."""

    error: BaseException


def close_iterator(iterator: Iterator[Frame]) -> None:
    """Close ``iterator`` if it can be closed (a generator: its ``finally`` blocks run)."""
    close = getattr(iterator, "close", None)
    if close is not None:
        close()


class ReaderThread(ABC):
    """A frame reader running on ``self.thread``: the thread starts when the ``with``
    block is entered and :meth:`close` ends it when the block is left, however it ends."""

    thread: threading.Thread

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    @abstractmethod
    def close(self) -> None:
        """Stop the thread and wait for it (idempotent)."""


class PrefetchedFrames(ReaderThread):
    """The frames of ``source``, read up to ``depth`` frames ahead on a thread (module doc).

    Use as a context manager; iterate it once inside the ``with`` block.

    Args:
        source: the frames (a :class:`~eslam.data.source.FrameSource` or any iterable).
        depth: frames read ahead at most (>= 1).
    """

    def __init__(self, source: Iterable[Frame], depth: int) -> None:
        if depth < 1:
            raise ValueError(f"depth must be >= 1, got {depth}")
        self._source = source
        self._queue: queue.Queue[Frame | _End | _Failure] = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._done = False
        self.thread = threading.Thread(target=self._read, name="eslam-prefetch", daemon=True)

    def _read(self) -> None:
        """The thread: read frames into the queue until the source ends or it is told to stop."""
        iterator: Iterator[Frame] | None = None
        try:
            iterator = iter(self._source)
            for frame in iterator:
                if not self._put(frame):
                    return
            self._put(_End())
        except BaseException as error:  # handed to the loop's thread, raised there
            self._put(_Failure(error))
        finally:
            if iterator is not None:
                try:
                    close_iterator(iterator)
                except Exception:  # a failing close must not hide the run's end
                    pass

    def _put(self, item: Frame | _End | _Failure) -> bool:
        """Queue ``item``, waiting for room; False when told to stop meanwhile."""
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=_POLL_S)
                return True
            except queue.Full:
                continue
        return False

    def __iter__(self) -> Iterator[Frame]:
        return self

    def __next__(self) -> Frame:
        if self._done:
            raise StopIteration
        while True:
            try:
                item = self._queue.get(timeout=_POLL_S)
                break
            except queue.Empty:
                if not self.thread.is_alive() and self._queue.empty():
                    self._done = True
                    raise RuntimeError("the frame reader thread ended without a word") from None
        if isinstance(item, _End):
            self._done = True
            raise StopIteration
        if isinstance(item, _Failure):
            self._done = True
            raise item.error
        return item

    def close(self) -> None:
        """Stop the thread and wait for it (again is fine)."""
        self._stop.set()
        self._done = True
        while True:  # free a thread blocked on a full queue
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(JOIN_TIMEOUT_S)
