"""Frame selection (``--start``, ``--stride``, ``--max-frames``) over any reader.

A :class:`FrameSelection` is itself an :class:`~eslam.data.base.RGBDSequence`, so the
run loop never knows whether it sees a whole sequence or part of it. Selected frames
are renumbered 0..N-1 (``Frame.index``) and keep their timestamps, so trajectories
written from a selection still associate with the dataset's ground truth.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from eslam.data.base import RGBDSequence
from eslam.errors import ConfigError
from eslam.types import Frame, Intrinsics


class FrameSelection:
    """Frames ``start, start + stride, ...`` of ``sequence``, at most ``max_frames`` of them.

    Args:
        sequence: any reader.
        start: first frame (0-based position in ``sequence``).
        stride: step between selected frames (>= 1).
        max_frames: upper limit on the number of frames, or None for all.

    Raises:
        ConfigError: a negative start, a stride below 1, a max_frames below 1, or a
            start at or past the end of the sequence.
    """

    def __init__(
        self,
        sequence: RGBDSequence,
        start: int = 0,
        stride: int = 1,
        max_frames: int | None = None,
    ) -> None:
        if start < 0:
            raise ConfigError(f"data.start must be >= 0, got {start}")
        if stride < 1:
            raise ConfigError(f"data.stride must be >= 1, got {stride}")
        if max_frames is not None and max_frames < 1:
            raise ConfigError(f"data.max_frames must be >= 1 or null, got {max_frames}")
        if start >= len(sequence):
            raise ConfigError(
                f"data.start={start} is past the end of {sequence.root} "
                f"({len(sequence)} frames): choose a start below {len(sequence)}"
            )
        positions = range(start, len(sequence), stride)
        if max_frames is not None:
            positions = positions[:max_frames]
        self.sequence = sequence
        self.positions = list(positions)
        self.root: Path = sequence.root
        self.intrinsics: Intrinsics = sequence.intrinsics

    def __len__(self) -> int:
        return len(self.positions)

    def __getitem__(self, index: int) -> Frame:
        if not 0 <= index < len(self):
            raise IndexError(f"frame {index} out of range for {len(self)} frames")
        frame = self.sequence[self.positions[index]]
        return dataclasses.replace(frame, index=index)

    def gt_poses(self) -> np.ndarray | None:
        """(N, 4, 4) ground-truth poses of the selected frames, or None."""
        poses = self.sequence.gt_poses()
        return None if poses is None else poses[self.positions]

    def timestamps(self) -> np.ndarray:
        """(N,) timestamps of the selected frames (seconds, or frame numbers)."""
        return sequence_timestamps(self.sequence)[self.positions]

    def frame_files(self, index: int) -> tuple[Path, Path]:
        """The (colour, depth) files of selected frame ``index`` (the reader's, if it has them).

        Raises:
            AttributeError: the reader does not read frames from files.
        """
        return self.sequence.frame_files(self.positions[index])  # type: ignore[attr-defined]


def sequence_timestamps(sequence: RGBDSequence) -> np.ndarray:
    """(N,) timestamps of every frame: the reader's ``timestamps()`` when it has one.

    Readers without it fall back to reading each frame's ``timestamp`` (slow: reads images).
    """
    method = getattr(sequence, "timestamps", None)
    if method is not None:
        return np.asarray(method(), dtype=np.float64)
    return np.array([sequence[i].timestamp for i in range(len(sequence))], dtype=np.float64)
