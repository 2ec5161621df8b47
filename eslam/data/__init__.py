"""Dataset readers: one module per layout, registered here by name.

``open_sequence(options)`` is the one way the rest of eslam opens data: it picks the
reader of ``options.format`` and applies the frame selection (start, stride, max_frames).
A reader is a callable ``reader(root: Path, options: DataConfig) -> RGBDSequence``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from eslam.config import DataConfig
from eslam.data.bags import effective_format
from eslam.data.base import RGBDSequence, iterate_frames
from eslam.data.depth_resolution import DepthDownsampled
from eslam.data.folder import FolderSequence
from eslam.data.realsense import RealSenseRecording
from eslam.data.redwood import RedwoodSequence
from eslam.data.replica import ReplicaSequence
from eslam.data.rosbag import RosbagSequence
from eslam.data.scannet import ScanNetSequence
from eslam.data.selection import FrameSelection, sequence_timestamps
from eslam.data.sevenscenes import SevenScenesSequence
from eslam.data.tum import TUMSequence
from eslam.errors import ConfigError

DATASETS: dict[str, Callable[[Path, DataConfig], RGBDSequence]] = {
    "replica": ReplicaSequence,
    "scannet": ScanNetSequence,
    "tum": TUMSequence,
    "sevenscenes": SevenScenesSequence,
    "folder": FolderSequence,
    "redwood": RedwoodSequence,
    "rosbag": RosbagSequence,
    "realsense": RealSenseRecording,
}
"""Reader of each supported layout, by the name ``data.format`` takes."""


def open_sequence(options: DataConfig) -> RGBDSequence:
    """Open ``options.path`` with the reader of ``options.format``, lower its depth
    resolution (``options.depth_downsample``, :mod:`eslam.data.depth_resolution`), then
    select frames.

    Raises:
        ConfigError: unknown layout, no path, or a frame selection outside the sequence.
        InputError: the folder is missing or its contents are invalid.
    """
    if options.path is None:
        raise ConfigError("data.path is not set (pass --data PATH or set data.path)")
    sequence = open_all_frames(options)
    if options.depth_downsample > 1:
        sequence = DepthDownsampled(sequence, options.depth_downsample)
    if options.start == 0 and options.stride == 1 and options.max_frames is None:
        return sequence
    return FrameSelection(sequence, options.start, options.stride, options.max_frames)


def open_all_frames(options: DataConfig) -> RGBDSequence:
    """Open every frame of ``options.path`` with the reader of ``options.format`` (a
    recording's own format when the path is one: :func:`~eslam.data.bags.effective_format`)."""
    format_name = effective_format(options.format, options.path)
    try:
        reader = DATASETS[format_name]
    except KeyError:
        choices = ", ".join(sorted(DATASETS))
        raise ConfigError(
            f"unknown data format '{format_name}' (choose one of: {choices})"
        ) from None
    return reader(Path(str(options.path)), options)


__all__ = [
    "DATASETS",
    "FrameSelection",
    "RGBDSequence",
    "effective_format",
    "iterate_frames",
    "open_all_frames",
    "open_sequence",
    "sequence_timestamps",
]
