"""How the run loop gets its frames: directly, read ahead, or newest-first in real time.

:func:`open_feed` chooses from ``data.realtime`` / ``data.prefetch`` and the source:

- real time (``data.realtime``, always for a live source): a
  :class:`~eslam.data.realtime.LatestFrameReader`, dropping frames that arrive while the
  loop is busy; a recording is replayed at its recorded rate (or ``data.replay_fps``),
  each frame read only when the loop takes it where the recording allows
  (:func:`pending_frames`);
- otherwise, with ``data.prefetch`` > 0: a :class:`~eslam.data.prefetch.PrefetchedFrames`
  reading that many frames ahead (the same frames in the same order);
- otherwise the source itself.

Use the feed as a context manager around the loop: leaving it stops its thread.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import partial
from types import TracebackType

from eslam.config import DataConfig
from eslam.data.prefetch import PrefetchedFrames, ReaderThread
from eslam.data.realtime import LatestFrameReader, Pending, ReplayPace
from eslam.data.selection import sequence_timestamps
from eslam.data.source import SequenceSource
from eslam.types import Frame


def is_live(source: object) -> bool:
    """Whether ``source`` is a live sensor (its ``live`` attribute; recordings have none):
    a live source always runs in real time and cannot be resumed."""
    return bool(getattr(source, "live", False))


def pending_frames(source: object) -> Iterator[Pending] | None:
    """A recorded sequence's frames as :class:`~eslam.data.realtime.Pending` ones, read
    when a replay's loop takes them; None when ``source`` cannot read a frame on demand
    or its reader has no timestamps of its own (reading them would read every frame)."""
    if not isinstance(source, SequenceSource):
        return None
    sequence = source.sequence
    if getattr(sequence, "timestamps", None) is None:
        return None
    stamps = sequence_timestamps(sequence)
    return (
        Pending(float(stamps[index]), partial(source.frame, index))
        for index in range(source.start, len(sequence))
    )


def runs_in_real_time(source: object, data: DataConfig) -> bool:
    """Whether a run on ``source`` drops frames it is too busy for (module doc)."""
    return data.realtime or is_live(source)


@dataclass(frozen=True, eq=False)
class Feed:
    """The frames the loop iterates, and the real-time reader behind them (None when the
    run is not real time)."""

    frames: Iterable[Frame]
    stream: LatestFrameReader | None

    def __enter__(self) -> Feed:
        if isinstance(self.frames, ReaderThread):
            self.frames.__enter__()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if isinstance(self.frames, ReaderThread):
            self.frames.close()


def open_feed(source: Iterable[Frame], data: DataConfig, name: str) -> Feed:
    """The feed of ``source`` (called ``name`` in messages) under ``data``'s settings
    (module doc); its thread starts when the ``with`` block is entered."""
    if runs_in_real_time(source, data):
        pace = None if is_live(source) else ReplayPace(data.replay_fps, name)
        pending = None if pace is None else pending_frames(source)
        reader = LatestFrameReader(source if pending is None else pending, pace)
        return Feed(reader, reader)
    if data.prefetch > 0:
        return Feed(PrefetchedFrames(source, data.prefetch), None)
    return Feed(source, None)
