"""Trajectory-to-depth consistency (eslam.evaluate.depth_consistency) on exact synthetic frames."""

from __future__ import annotations

import numpy as np
import pytest

from eslam.evaluate.depth_consistency import depth_residuals, pair_consistency
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.types import Frame


@pytest.fixture(scope="module")
def frames() -> list[Frame]:
    config = SynthConfig(frames=6, width=160, height=120, seed=3, step_translation=0.02)
    return list(generate_sequence(config))


def _moved_along_view(pose: np.ndarray, metres: float) -> np.ndarray:
    """The camera moved ``metres`` along its own optical axis."""
    step = np.eye(4)
    step[2, 3] = metres
    return pose @ step


def _turned_around(pose: np.ndarray) -> np.ndarray:
    """The same camera centre looking the other way (half a turn about its y axis)."""
    return pose @ np.diag([-1.0, 1.0, -1.0, 1.0])


def test_ground_truth_poses_agree_with_exact_depth(frames: list[Frame]) -> None:
    a, b = frames[0], frames[5]
    residual = depth_residuals(a.depth, b.depth, a.intrinsics, a.pose_gt, b.pose_gt, every=2)
    seen = np.isfinite(residual)
    assert seen.mean() > 0.5
    # Exact depth: only the nearest-pixel lookup on slanted surfaces remains (half a
    # pixel at 160x120 moves the depth by ~3 mm here).
    assert np.median(np.abs(residual[seen])) < 5e-3


def test_pixels_without_depth_or_outside_are_nan(frames: list[Frame]) -> None:
    a, b = frames[0], frames[1]
    depth = a.depth.copy()
    depth[:, :40] = 0.0
    residual = depth_residuals(depth, b.depth, a.intrinsics, a.pose_gt, b.pose_gt, every=1)
    assert np.isnan(residual.reshape(depth.shape)[:, :40]).all()
    away = _turned_around(a.pose_gt)  # every point is behind it
    assert np.isnan(depth_residuals(a.depth, b.depth, a.intrinsics, a.pose_gt, away)).all()


def test_a_pose_error_raises_the_median_on_the_same_pixels(frames: list[Frame]) -> None:
    a, b = frames[0], frames[4]
    wrong = _moved_along_view(b.pose_gt, 0.015)
    result = pair_consistency(
        a.depth, b.depth, a.intrinsics, [(a.pose_gt, b.pose_gt), (a.pose_gt, wrong)]
    )
    assert result.pixels > 100
    truth, off = result.medians
    assert truth < 5e-3
    assert 0.01 < off < 0.02, off


def test_no_common_pixel_gives_nan(frames: list[Frame]) -> None:
    a, b = frames[0], frames[1]
    away = _turned_around(a.pose_gt)
    result = pair_consistency(
        a.depth, b.depth, a.intrinsics, [(a.pose_gt, b.pose_gt), (a.pose_gt, away)]
    )
    assert result.pixels == 0
    assert np.isnan(result.medians).all()
