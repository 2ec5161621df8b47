"""Fixtures of the recording readers' tests: a tiny synthetic sequence's frames."""

from __future__ import annotations

from pathlib import Path

import pytest

SMALL_FRAMES = 5
"""Frames of :func:`small_frames` (64x48, seed 3)."""


@pytest.fixture(scope="session")
def small_frames(tmp_path_factory: pytest.TempPathFactory) -> list:
    """Five 64x48 synthetic frames with ground truth (read back from the Replica layout)."""
    from eslam.config import DataConfig
    from eslam.data import open_sequence
    from eslam.synthetic import SynthConfig, write_synthetic_sequence

    root: Path = tmp_path_factory.mktemp("small") / "data"
    config = SynthConfig(frames=SMALL_FRAMES, width=64, height=48, seed=3)
    write_synthetic_sequence(root, config)
    sequence = open_sequence(DataConfig(path=str(root)))
    return [sequence[i] for i in range(len(sequence))]
