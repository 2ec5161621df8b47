"""Frame sources: what the run loop consumes, recorded or live.

A :class:`FrameSource` has the camera's intrinsics and yields :class:`~eslam.types.Frame`
objects in order; its length is optional (a camera stream has none). Recorded sequences
(every reader in :mod:`eslam.data`) adapt to it with :class:`SequenceSource`; any
iterable of frames (a generator, a queue reader, a sensor driver) with
:class:`IterableSource`.

Each frame brings its own timestamp and ground-truth pose (``Frame.timestamp``,
``Frame.pose_gt``): the loop collects them frame by frame, so nothing needs the whole
sequence up front.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from eslam.data.base import RGBDSequence
from eslam.types import Frame, Intrinsics


@runtime_checkable
class FrameSource(Protocol):
    """Frames in order, from a recording or a live stream.

    Attributes:
        intrinsics: the camera of every frame.
        name: what to call the source in messages (a folder, a device, "stream").

    A live sensor (a camera) also sets ``live = True`` (an optional attribute, read with
    :func:`eslam.data.feed.is_live`): its runs are real time (frames it delivers while the
    system is busy are dropped) and cannot be resumed. Recordings have no such attribute
    or set it False.
    """

    intrinsics: Intrinsics
    name: str

    def __iter__(self) -> Iterator[Frame]:
        """The frames, in order; may be endless. Errors reading one raise InputError."""
        ...


def source_length(source: FrameSource) -> int | None:
    """Frames ``source`` will yield, or None when it does not know (a live stream)."""
    length = getattr(source, "__len__", None)
    return None if length is None else int(length())


@dataclass(frozen=True)
class SequenceSource:
    """A recorded sequence as a frame source, from frame ``start`` on (resume).

    Attributes:
        sequence: the sequence (after the reader's frame selection).
        start: the first frame yielded.
    """

    sequence: RGBDSequence
    start: int = 0

    @property
    def intrinsics(self) -> Intrinsics:
        """The sequence's camera."""
        return self.sequence.intrinsics

    @property
    def name(self) -> str:
        """The sequence's folder."""
        return str(self.sequence.root)

    @property
    def root(self) -> Path:
        """The sequence's folder."""
        return self.sequence.root

    def __len__(self) -> int:
        return max(len(self.sequence) - self.start, 0)

    def __iter__(self) -> Iterator[Frame]:
        for index in range(self.start, len(self.sequence)):
            yield self.sequence[index]

    def frame(self, index: int) -> Frame:
        """Frame ``index`` of the sequence (random access, e.g. to re-read the last one)."""
        return self.sequence[index]


class IterableSource:
    """Frames from any iterable (a generator, a driver loop), length unknown unless given.

    Args:
        intrinsics: the camera of every frame.
        frames: the frames, in order (consumed once).
        name: what to call the source in messages.
        live: the frames come from a live sensor (see :class:`FrameSource`).
    """

    def __init__(
        self,
        intrinsics: Intrinsics,
        frames: Iterable[Frame],
        name: str = "stream",
        live: bool = False,
    ):
        self.intrinsics = intrinsics
        self.name = name
        self.live = live
        self._frames = frames

    def __iter__(self) -> Iterator[Frame]:
        return iter(self._frames)
