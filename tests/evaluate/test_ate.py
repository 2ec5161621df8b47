"""ATE: known transforms give zero error, and the evo reference values are reproduced."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eslam.evaluate.trajectory import (
    absolute_trajectory_error,
    associate_timestamps,
    umeyama_alignment,
)


def test_rotated_and_shifted_trajectory_has_zero_error() -> None:
    rng = np.random.default_rng(0)
    positions = np.cumsum(rng.normal(scale=0.05, size=(100, 3)), axis=0)
    rotation = Rotation.from_rotvec([0.3, -1.2, 2.0]).as_matrix()
    moved = positions @ rotation.T + np.array([1.0, -2.0, 0.5])
    result = absolute_trajectory_error(moved, positions)
    assert result.rmse < 1e-12 and result.pairs == 100
    np.testing.assert_allclose(result.alignment.rotation, rotation.T, atol=1e-12)


def test_scale_is_recovered_only_when_asked() -> None:
    rng = np.random.default_rng(1)
    positions = rng.normal(size=(50, 3))
    scaled = 2.0 * positions
    assert absolute_trajectory_error(scaled, positions).rmse > 0.1
    result = absolute_trajectory_error(scaled, positions, with_scale=True)
    assert result.rmse < 1e-12 and abs(result.alignment.scale - 0.5) < 1e-12


def test_known_error_of_a_single_offset_point() -> None:
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, :3, 3] = positions
    estimated = poses.copy()
    estimated[0, 2, 3] += 0.04  # one point 4 cm off: rigid alignment spreads it
    result = absolute_trajectory_error(estimated, poses)
    assert 0.0 < result.rmse < 0.04
    assert result.max <= 0.04


def test_non_finite_rows_are_left_out() -> None:
    positions = np.random.default_rng(2).normal(size=(10, 3))
    estimated = positions.copy()
    estimated[3] = np.nan
    assert absolute_trajectory_error(estimated, positions).pairs == 9


def test_reflection_is_never_returned() -> None:
    points = np.random.default_rng(3).normal(size=(20, 3))
    mirrored = points * np.array([1.0, 1.0, -1.0])
    alignment = umeyama_alignment(points, mirrored)
    assert np.linalg.det(alignment.rotation) > 0


def test_association_is_one_to_one_nearest_first() -> None:
    first = np.array([0.0, 1.0, 2.0, 3.0])
    second = np.array([0.004, 0.006, 2.02, 3.001])
    i, j = associate_timestamps(first, second, 0.01)
    assert i.tolist() == [0, 3] and j.tolist() == [0, 3]


def _tum(path: Path) -> np.ndarray:
    return np.loadtxt(path, comments="#")


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("gt", "est", "pairs", "rmse", "mean", "max_error", "rmse_sim3"),
    [
        (
            "freiburg1_xyz-groundtruth.txt",
            "freiburg1_xyz-rgbdslam.txt",
            785,
            0.013470,
            0.012024,
            0.034760,
            0.013389,
        ),
        ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", 2174, 0.008119, None, 0.024300, 0.006123),
    ],
)
def test_evo_reference_values(
    real_data: Path, gt, est, pairs, rmse, mean, max_error, rmse_sim3
) -> None:
    ground_truth = _tum(real_data / "tum-trajectories" / gt)
    estimate = _tum(real_data / "tum-trajectories" / est)
    i, j = associate_timestamps(estimate[:, 0], ground_truth[:, 0], 0.01)
    result = absolute_trajectory_error(estimate[i, 1:4], ground_truth[j, 1:4])
    assert result.pairs == pairs
    assert abs(result.rmse - rmse) < 1e-5
    assert abs(result.max - max_error) < 1e-5
    if mean is not None:
        assert abs(result.mean - mean) < 1e-5
    similarity = absolute_trajectory_error(estimate[i, 1:4], ground_truth[j, 1:4], with_scale=True)
    assert abs(similarity.rmse - rmse_sim3) < 1e-5
