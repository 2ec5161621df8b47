"""benchmarks/observed_share.py: the share of each frame in space the keyframes observed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.synthetic import read_synthetic_bound
from eslam.testing.scripts import load_script
from tests.conftest import TINY_FRAMES

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "observed_share.py"
DEMO = Path(__file__).resolve().parents[1] / "configs" / "demo.yaml"


@pytest.fixture(scope="module")
def script():
    return load_script(SCRIPT)


def test_fewer_keyframes_observe_less_of_the_later_frames(script, tiny_sequence: Path) -> None:
    bound = f"scene.bound={read_synthetic_bound(tiny_sequence)}"

    def shares(every: int) -> np.ndarray:
        overrides = (bound, f"mapping.every={every}")
        return script.observed_shares(DEMO, tiny_sequence, TINY_FRAMES, overrides)

    every_frame, first_only = shares(1), shares(100)
    assert every_frame.shape == (TINY_FRAMES - 1,)
    assert every_frame.min() > 0.95  # the previous frame sees nearly all of the next
    # a superset of keyframes observes a superset of space
    assert bool(np.all(first_only <= every_frame))
    # the camera moves on: frame 0 alone no longer sees all of the last frames
    assert first_only[-3:].max() < every_frame[-3:].min()


def test_main_prints_the_table(script, tiny_sequence: Path, capsys) -> None:
    bound = f"scene.bound={read_synthetic_bound(tiny_sequence)}"
    argv = ["--config", str(DEMO), "--data", str(tiny_sequence), "--frames", str(TINY_FRAMES)]
    script.main([*argv, "--segment", "5", "--no-append", bound])
    out = capsys.readouterr().out
    assert "| 1-5 |" in out and "| 6-10 |" in out and "| 11-11 |" in out
