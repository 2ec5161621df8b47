"""Opening ROS bags (ROS 1 ``.bag``, ROS 2 folders and their ``.db3``/``.mcap`` files) and
telling what a recording is, for the readers and the format detection.

``data.format`` names a folder layout by default (``replica``); when ``data.path`` is a
recording, :func:`effective_format` picks ``rosbag`` or ``realsense`` instead, since no
folder layout could read it: a RealSense recording (librealsense's ``/file_version`` and
``/device_0/...`` topics) is played back with the SDK, any other bag read with rosbags.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from eslam.config import DataConfig
from eslam.errors import InputError

RECORDING_FORMATS = ("rosbag", "realsense")
"""``data.format`` values that read recordings rather than folders."""

BAG_SUFFIXES = (".bag", ".db3", ".mcap")
"""File suffixes of ROS 1 bags and ROS 2 bag storage files."""

REALSENSE_TOPIC_MARKS = ("/file_version", "/device_0/")
"""Topics (or topic prefixes) only librealsense's recorder writes."""


def is_recording(path: Path) -> bool:
    """Whether ``path`` is a bag file or a ROS 2 bag folder (holding metadata.yaml)."""
    if path.is_file():
        return path.suffix.lower() in BAG_SUFFIXES
    return path.is_dir() and (path / "metadata.yaml").is_file()


def bag_location(path: Path) -> Path:
    """What rosbags opens for ``path``: a .db3/.mcap file inside a ROS 2 bag folder opens
    the folder (all its files, in the metadata's order); anything else as it is."""
    if path.suffix.lower() in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        return path.parent
    return path


def open_bag(path: Path):
    """An open ``rosbags.highlevel.AnyReader`` of the bag at ``path`` (close it when done).

    ROS 2 storage files without embedded message definitions (librealsense's ``.db3``)
    are read with the ROS 2 Humble types.

    Raises:
        InputError: the path is missing or not a readable bag.
    """
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    if not path.exists():
        raise InputError(path, "recording not found", "check the --data path")
    if not is_recording(path):
        raise InputError(
            path,
            "is not a ROS bag (a .bag, .db3 or .mcap file, or a folder with metadata.yaml)",
            "pass the recording itself to --data",
        )
    reader = AnyReader([bag_location(path)], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    try:
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as error:
        raise InputError(
            path, f"not a readable ROS bag ({error})", "re-record or re-export it"
        ) from None
    return reader


def bag_topics(path: Path) -> dict[str, str]:
    """Topic name -> message type of the bag at ``path`` (opened and closed here)."""
    reader = open_bag(path)
    try:
        return {name: str(info.msgtype) for name, info in reader.topics.items()}
    finally:
        reader.close()


def is_realsense_recording(path: Path) -> bool:
    """Whether the bag at ``path`` was written by librealsense (its marker topics)."""
    topics = bag_topics(path)
    return any(
        name == mark or name.startswith(mark) for name in topics for mark in REALSENSE_TOPIC_MARKS
    )


def recording_format(path: Path) -> str | None:
    """``realsense`` or ``rosbag`` for a recording at ``path``, None for anything else."""
    if not is_recording(path):
        return None
    if path.is_file() and path.suffix.lower() in (".bag", ".db3") and is_realsense_recording(path):
        return "realsense"
    return "rosbag"


def effective_format(format_name: str, path: str | Path | None) -> str:
    """The reader to use: ``format_name``, unless it names a folder layout and ``path``
    is a recording, whose own format (:func:`recording_format`) is then used."""
    if format_name in RECORDING_FORMATS or path is None:
        return format_name
    detected = recording_format(Path(str(path)))
    return detected if detected is not None else format_name


def with_detected_format(options: DataConfig) -> DataConfig:
    """``options`` with ``format`` set to :func:`effective_format` (what a run records)."""
    detected = effective_format(options.format, options.path)
    return options if detected == options.format else dataclasses.replace(options, format=detected)
