"""A run stopped right after a failed frame resumes exactly: the motion model's "hold
still after a failure" is read from the checkpointed quality rows, not from the loop."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from eslam.config import load_config
from eslam.slam.session import run_slam
from tests.conftest import TINY_FRAMES, tiny_config

pytestmark = pytest.mark.slow  # three tiny runs

FAILED = 7
"""The frame whose depth is replaced by noise (the SDF tracker judges it failed)."""


@pytest.fixture(scope="module")
def noisy_sequence(tiny_sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny sequence with frame 7's depth replaced by uniform noise (same units)."""
    root = tmp_path_factory.mktemp("noisy") / "data"
    shutil.copytree(tiny_sequence, root)
    path = root / "results" / f"depth{FAILED:06d}.png"
    depth = np.asarray(Image.open(path))
    noise = np.random.default_rng(0).integers(1, 3 * int(depth.max()), size=depth.shape)
    Image.fromarray(noise.astype(depth.dtype)).save(path)
    return root


def test_a_run_stopped_right_after_a_failed_frame_resumes_exactly(
    noisy_sequence: Path, tmp_path: Path
) -> None:
    config = tiny_config(noisy_sequence, "tracking.method=hybrid", "output.mesh=false")
    whole = run_slam(config, tmp_path / "whole")
    assert whole.metrics["tracking_failures"] == 1
    assert f"frame {FAILED} (timestamp" in (tmp_path / "whole" / "log.txt").read_text()
    out = tmp_path / "stopped"
    run_slam(config, out, stop_after=FAILED + 1)  # the failed frame is the last one saved
    resumed = run_slam(load_config(out / "config.yaml"), out, resume=True)
    assert len(resumed.poses) == TINY_FRAMES
    # every frame, those before the stop included (later mapping calls refine them)
    np.testing.assert_allclose(resumed.poses, whole.poses, rtol=0, atol=1e-7)
