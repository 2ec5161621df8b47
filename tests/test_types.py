"""Intrinsics and Frame: validation at construction, so bad values fail where they enter."""

from __future__ import annotations

import numpy as np
import pytest

from eslam.types import Frame, Intrinsics

K = Intrinsics(width=4, height=3, fx=2.0, fy=2.0, cx=1.5, cy=1.0)


def test_matrix() -> None:
    np.testing.assert_array_equal(K.matrix(), [[2.0, 0.0, 1.5], [0.0, 2.0, 1.0], [0.0, 0.0, 1.0]])
    assert K.size == (4, 3)


@pytest.mark.parametrize(
    "values",
    [(0, 3, 2.0, 2.0, 1.5, 1.0), (4, 3, -1.0, 2.0, 1.5, 1.0), (4, 3, 2.0, float("nan"), 1.5, 1.0)],
)
def test_invalid_intrinsics(values: tuple) -> None:
    with pytest.raises(ValueError):
        Intrinsics(*values)


def test_crop_that_leaves_nothing() -> None:
    with pytest.raises(ValueError, match="crop leaves no image"):
        K.cropped(2, 0, 2, 0)
    with pytest.raises(ValueError, match="non-negative"):
        K.cropped(-1, 0)


def test_frame_checks_shapes_and_dtypes() -> None:
    rgb = np.zeros((3, 4, 3), dtype=np.uint8)
    depth = np.array([[0, 1, 2, np.nan]] * 3, dtype=np.float32)
    frame = Frame(0, rgb, depth, K)
    np.testing.assert_array_equal(frame.valid_depth[0], [False, True, True, False])
    with pytest.raises(ValueError, match=r"rgb must be \(3, 4, 3\) uint8"):
        Frame(0, rgb.astype(np.float32), depth, K)
    with pytest.raises(ValueError, match=r"depth must be \(3, 4\) float32"):
        Frame(0, rgb, depth.T.copy(), K)
    with pytest.raises(ValueError, match="pose_gt must be 4x4"):
        Frame(0, rgb, depth, K, pose_gt=np.eye(3))
