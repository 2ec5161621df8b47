"""ATE: known transforms give zero error, and the evo reference values are reproduced."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eslam.evaluate.trajectory import (
    TimedPoses,
    absolute_trajectory_error,
    associate_timestamps,
    trajectory_ate,
    umeyama_alignment,
)
from eslam.io.trajectory import read_trajectory


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


def test_median_and_max_match_an_independent_kabsch_alignment() -> None:
    """scipy's Rotation.align_vectors solves the same rigid fit (Kabsch) on centred points."""
    rng = np.random.default_rng(4)
    gt = rng.normal(size=(40, 3))
    rotation = Rotation.from_rotvec([0.4, -0.2, 0.9]).as_matrix()
    estimate = gt @ rotation.T + [0.5, 0.1, -2.0] + rng.normal(scale=0.02, size=gt.shape)
    fit, _ = Rotation.align_vectors(gt - gt.mean(axis=0), estimate - estimate.mean(axis=0))
    aligned = fit.apply(estimate - estimate.mean(axis=0)) + gt.mean(axis=0)
    errors = np.linalg.norm(aligned - gt, axis=1)
    result = absolute_trajectory_error(estimate, gt)
    assert result.median == pytest.approx(np.median(errors), abs=1e-12)
    assert result.max == pytest.approx(errors.max(), abs=1e-12)
    assert result.mean == pytest.approx(errors.mean(), abs=1e-12)
    assert result.rmse == pytest.approx(np.sqrt(np.mean(errors**2)), abs=1e-12)
    assert 0.01 < result.median < result.max


def _timed(times: np.ndarray, positions: np.ndarray) -> TimedPoses:
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    poses[:, :3, 3] = positions
    return TimedPoses(times, poses)


def test_missing_ground_truth_poses_are_excluded_and_counted() -> None:
    rng = np.random.default_rng(6)
    positions = np.cumsum(rng.normal(scale=0.1, size=(30, 3)), axis=0)
    rotation = Rotation.from_rotvec([0.1, 0.2, -0.3]).as_matrix()
    gt = _timed(np.arange(30.0), positions)
    gt.poses[[4, 9, 17]] = np.nan
    estimate = _timed(np.arange(30.0) + 0.004, positions @ rotation.T + 1.0)
    estimate.poses[2, 0, 0] = np.inf  # a broken estimate counts as missing too
    result = trajectory_ate(gt, estimate)
    assert result.pairs == 26 and result.excluded == 4 and result.rmse < 1e-12
    assert result.as_dict()["excluded"] == 4 and result.as_dict()["pairs"] == 26


def test_association_window_and_too_few_pairs() -> None:
    positions = np.random.default_rng(7).normal(size=(10, 3))
    gt = _timed(np.arange(10.0), positions)
    late = _timed(np.arange(10.0) + 0.02, positions)
    with pytest.raises(ValueError, match=r"only 0 poses matched within 0\.01 s"):
        trajectory_ate(gt, late)
    assert trajectory_ate(gt, late, max_difference=0.03).pairs == 10


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("gt", "est", "pairs", "rmse", "max_error", "rmse_sim3"),
    [
        (
            "freiburg1_xyz-groundtruth.txt",
            "freiburg1_xyz-rgbdslam.txt",
            785,
            0.01347,
            0.03476,
            0.013389,
        ),
        ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", 2174, 0.008119, 0.0243, 0.006123),
    ],
)
def test_evo_reference_values_from_files(
    real_data: Path, gt, est, pairs, rmse, max_error, rmse_sim3
) -> None:
    """The file path the `eslam ate` command takes: read_trajectory, then trajectory_ate."""
    folder = real_data / "tum-trajectories"
    ground_truth = TimedPoses(*read_trajectory(folder / gt, ground_truth=True))
    estimate = TimedPoses(*read_trajectory(folder / est))
    result = trajectory_ate(ground_truth, estimate)
    assert result.pairs == pairs and result.excluded == 0
    assert abs(result.rmse - rmse) < 1e-5 and abs(result.max - max_error) < 1e-5
    assert result.median <= result.rmse
    assert abs(trajectory_ate(ground_truth, estimate, with_scale=True).rmse - rmse_sim3) < 1e-5
