"""The configuration tree: one dataclass per section, a docstring under every field.

A ``__post_init__`` check raises ValueError starting with the field's name ("threads
must be >= 0, ...") so the loader can name the file that set that field.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field


@dataclass
class DataConfig:
    """Which sequence to read and how it is laid out on disk."""

    format: str = "replica"
    """Dataset layout of the sequence folder (e.g. replica); checked by the data layer."""
    path: str | None = None
    """Folder of the sequence; `--data PATH` on the command line sets it."""


@dataclass
class SceneConfig:
    """The region of space the map covers."""

    bound: list[list[float]] | None = None
    """Scene box [[xmin, xmax], [ymin, ymax], [zmin, zmax]] in metres; null = automatic."""

    def __post_init__(self) -> None:
        if self.bound is not None and (
            len(self.bound) != 3 or any(len(p) != 2 or not p[0] < p[1] for p in self.bound)
        ):
            raise ValueError(f"bound must be 3 pairs [min, max] with min < max, got {self.bound}")


@dataclass
class ESLAMConfig:
    """Everything a run needs; saved fully resolved as config.yaml in the run folder."""

    seed: int = 0
    """Seed of every random generator; the same seed gives the same numbers on CPU."""
    device: str = "cpu"
    """Torch device to run on: cpu, cuda, cuda:N or mps."""
    threads: int = 2
    """Torch intra-op CPU threads; 0 leaves torch's default."""
    data: DataConfig = field(default_factory=DataConfig)
    """The input sequence."""
    scene: SceneConfig = field(default_factory=SceneConfig)
    """The mapped region of space."""

    def __post_init__(self) -> None:
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if self.threads < 0:
            raise ValueError(f"threads must be >= 0 (0 = torch's default), got {self.threads}")
        if not re.fullmatch(r"cpu|mps|cuda(:\d+)?", self.device):
            raise ValueError(f"device must be cpu, cuda, cuda:N or mps, got '{self.device}'")
