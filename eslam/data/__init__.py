"""Dataset readers: one module per layout, registered here by name.

``open_sequence(format, path)`` is the one way the rest of eslam opens data.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from eslam.data.base import RGBDSequence, iterate_frames
from eslam.data.replica import ReplicaSequence
from eslam.errors import ConfigError

DATASETS: dict[str, Callable[[Path], RGBDSequence]] = {
    "replica": ReplicaSequence,
}
"""Reader of each supported layout, by the name ``data.format`` takes."""


def open_sequence(format_name: str, path: str | Path) -> RGBDSequence:
    """Open the sequence at ``path`` with the reader registered as ``format_name``.

    Raises:
        ConfigError: ``format_name`` is not a registered layout.
        InputError: the folder is missing or its contents are invalid.
    """
    try:
        reader = DATASETS[format_name]
    except KeyError:
        choices = ", ".join(sorted(DATASETS))
        raise ConfigError(
            f"unknown data format '{format_name}' (choose one of: {choices})"
        ) from None
    return reader(Path(path))


__all__ = ["DATASETS", "RGBDSequence", "iterate_frames", "open_sequence"]
