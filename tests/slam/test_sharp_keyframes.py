"""Keyframes from sharp frames (``mapping.blur_defer``, eslam/slam/mapping/sharp_keyframes.py):
the sharpness measure, the blur test against the recent frames, the deferral's rule, and
a run whose due keyframe falls on a blurred frame."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from eslam.config import load_config
from eslam.errors import ConfigError
from eslam.io.checkpoint import load_checkpoint
from eslam.slam.mapping.sharp_keyframes import (
    HISTORY,
    MIN_HISTORY,
    BlurDeferral,
    image_sharpness,
    is_blurred,
)
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig, SyntheticSequence
from tests.conftest import tiny_config


def _blurred(rgb: np.ndarray, sigma: float = 2.0) -> np.ndarray:
    return cv2.GaussianBlur(rgb, (0, 0), sigma)


@pytest.fixture(scope="module")
def room_rgb() -> np.ndarray:
    return SyntheticSequence(SynthConfig(frames=1, width=160, height=120, seed=0))[0].rgb


def test_sharpness_falls_with_blur(room_rgb: np.ndarray) -> None:
    sharp = image_sharpness(room_rgb)
    assert sharp > 0
    assert image_sharpness(_blurred(room_rgb, 1.0)) < 0.6 * sharp
    assert image_sharpness(_blurred(room_rgb, 3.0)) < image_sharpness(_blurred(room_rgb, 1.0))
    assert image_sharpness(np.full_like(room_rgb, 128)) == 0.0
    with pytest.raises(ValueError, match="colour image"):
        image_sharpness(room_rgb[..., 0])


def test_blur_is_judged_against_the_recent_median() -> None:
    history = [1.0, 1.2, 0.8]
    assert is_blurred(0.6, history, 0.7) and not is_blurred(0.8, history, 0.7)
    assert not is_blurred(0.0, history[: MIN_HISTORY - 1], 0.7)  # too little known
    assert is_blurred(0.6, [*history, 100.0, 0.1], 0.7)  # the median, not the mean


def _state(sharpness: float, frames: int) -> dict:
    return {"sharpness": [sharpness] * frames}


def test_a_due_keyframe_waits_for_a_sharp_frame(room_rgb: np.ndarray) -> None:
    rule = BlurDeferral(defer=2, ratio=0.7)
    sharp, blurred = room_rgb, _blurred(room_rgb)
    own = _state(image_sharpness(sharp), 5)
    assert not rule.take(True, blurred, own) and own["waited"] == 1
    assert rule.take(False, sharp, own) and "waited" not in own  # the next sharp frame
    assert len(own["sharpness"]) == 7
    assert not rule.take(False, sharp, own)  # nothing due

    own = _state(image_sharpness(sharp), 5)
    assert not rule.take(True, blurred, own)
    assert not rule.take(False, None, own) and own["waited"] == 2  # failed: waits on
    assert rule.take(False, blurred, own) and "waited" not in own  # waited its most

    own = _state(image_sharpness(sharp), 2 * HISTORY)
    assert rule.take(True, sharp, own) and len(own["sharpness"]) == HISTORY


def test_no_deferral_is_the_fixed_interval(room_rgb: np.ndarray) -> None:
    rule, own = BlurDeferral(defer=0, ratio=0.7), _state(1.0, 5)
    assert rule.take(True, _blurred(room_rgb), own) and not rule.take(False, room_rgb, own)
    assert own == _state(1.0, 5)  # nothing measured
    with pytest.raises(ValueError, match="blur_defer"):
        BlurDeferral(defer=-1, ratio=0.7)
    for ratio in (0.0, 1.5):
        with pytest.raises(ValueError, match="blur_ratio"):
            BlurDeferral(defer=1, ratio=ratio)


def test_settings_are_checked() -> None:
    for setting in ("mapping.blur_defer=-1", "mapping.blur_ratio=0", "mapping.blur_ratio=2"):
        with pytest.raises(ConfigError, match="blur_"):
            load_config("demo", [setting])


BLURRED_FRAME = 6
"""A keyframe is due there (the tiny settings map every 3rd frame)."""


@pytest.fixture(scope="module")
def blurred_sequence(tiny_sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny sequence with frame :data:`BLURRED_FRAME`'s colour blurred."""
    root = tmp_path_factory.mktemp("blurred") / "data"
    shutil.copytree(tiny_sequence, root)
    path = root / "results" / f"frame{BLURRED_FRAME:06d}.jpg"
    cv2.imwrite(str(path), _blurred(cv2.imread(str(path)), 2.0))
    return root


def _keyframes(run_dir: Path) -> list[int]:
    return [int(i) for i in load_checkpoint(run_dir / "map.pt")["keyframes"]["frame_indices"]]


def test_a_run_takes_the_frame_after_a_blurred_one(blurred_sequence: Path, tmp_path) -> None:
    fixed = run_slam(tiny_config(blurred_sequence), tmp_path / "fixed")
    deferred = run_slam(tiny_config(blurred_sequence, "mapping.blur_defer=2"), tmp_path / "sharp")
    assert _keyframes(fixed.run_dir) == [0, 3, 6, 9, 11]
    assert _keyframes(deferred.run_dir) == [0, 3, 7, 9, 11]
    # the rule's state is saved with the run
    saved = load_checkpoint(deferred.run_dir / "map.pt")["components"]["sharp_keyframes"]
    assert len(saved["sharpness"]) == 12 and "waited" not in saved
