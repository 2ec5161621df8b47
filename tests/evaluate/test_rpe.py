"""RPE: invariant to the world frame, known errors by hand, evo's reference values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eslam.evaluate.trajectory import (
    TimedPoses,
    associate_timestamps,
    pair_errors,
    relative_pose_error,
    trajectory_rpe,
)
from eslam.io.trajectory import read_trajectory


def _walk(frames: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (frames, 1, 1))
    poses[:, :3, :3] = Rotation.from_rotvec(
        np.cumsum(rng.normal(0, 0.02, (frames, 3)), 0)
    ).as_matrix()
    poses[:, :3, 3] = np.cumsum(rng.normal(0, 0.01, (frames, 3)), axis=0)
    return poses


def _line(frames: int, step: float = 0.01) -> np.ndarray:
    poses = np.tile(np.eye(4), (frames, 1, 1))
    poses[:, 0, 3] = step * np.arange(frames)
    return poses


def test_another_world_frame_has_zero_error() -> None:
    truth = _walk(50)
    world = np.eye(4)
    world[:3, :3] = Rotation.from_rotvec([0.4, -1.0, 2.2]).as_matrix()
    world[:3, 3] = [3.0, -1.0, 0.5]
    result = relative_pose_error(world @ truth, truth)
    assert result.pairs == 49 and result.translation_rmse < 1e-12 and result.rotation_rmse < 1e-5


def test_one_displaced_pose_errs_in_its_two_pairs() -> None:
    truth = _line(5)
    estimate = truth.copy()
    estimate[2, 1, 3] += 0.003
    result = relative_pose_error(estimate, truth)
    # pairs (0,1) (1,2) (2,3) (3,4): errors 0, 3, 3, 0 mm
    assert result.pairs == 4
    assert result.translation_rmse == pytest.approx(np.sqrt(2 * 0.003**2 / 4), abs=1e-12)
    assert result.translation_median == pytest.approx(0.0015, abs=1e-12)
    assert result.rotation_rmse == pytest.approx(0.0, abs=1e-6)


def test_one_turned_pose_errs_by_its_angle_and_its_lever_arm() -> None:
    truth = _line(3, step=0.01)
    estimate = truth.copy()
    estimate[1, :3, :3] = Rotation.from_rotvec([0.0, 0.0, np.radians(1.0)]).as_matrix()
    result = relative_pose_error(estimate, truth)
    # pair (0,1): rotation 1 deg, no translation error; pair (1,2): 1 deg, and the 1 cm
    # step seen from the turned camera: |R^-1 t - t| = 2 * 0.01 * sin(0.5 deg)
    lever = 2 * 0.01 * np.sin(np.radians(0.5))
    assert result.rotation_median == pytest.approx(1.0, abs=1e-6)
    assert result.translation_rmse == pytest.approx(np.sqrt(lever**2 / 2), rel=1e-6)


def test_delta_and_missing_poses() -> None:
    truth = _line(10)
    estimate = truth.copy()
    estimate[:, 2, 3] += 0.001 * np.arange(10)  # drifts 1 mm per frame along z
    estimate[4] = np.nan
    one = relative_pose_error(estimate, truth)
    assert one.pairs == 7 and one.translation_median == pytest.approx(0.001, abs=1e-12)
    three = relative_pose_error(estimate, truth, delta=3)
    assert three.pairs == 5 and three.translation_rmse == pytest.approx(0.003, abs=1e-12)
    assert three.as_dict()["rpe_translation_rmse_mm"] == pytest.approx(3.0)


def test_each_pair_keeps_its_error_and_first_index() -> None:
    truth = _line(6)
    estimate = truth.copy()
    estimate[2, 1, 3] += 0.003
    estimate[4] = np.nan
    pairs = pair_errors(estimate, truth)
    # pairs (0,1) (1,2) (2,3): 0, 3, 3 mm; (3,4) and (4,5) have a missing pose
    assert pairs.first.tolist() == [0, 1, 2]
    assert pairs.translation == pytest.approx([0.0, 0.003, 0.003], abs=1e-12)
    assert pairs.rotation == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="delta"):
        relative_pose_error(_line(4), _line(4), delta=0)
    with pytest.raises(ValueError, match=r"\(N, 4, 4\)"):
        relative_pose_error(_line(4), _line(5))
    lonely = _line(4)
    lonely[[1, 3]] = np.nan
    with pytest.raises(ValueError, match="no pair"):
        relative_pose_error(lonely, _line(4))


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("gt", "est", "pairs", "translation", "rotation"),
    [
        (
            "freiburg1_xyz-groundtruth.txt",
            "freiburg1_xyz-rgbdslam.txt",
            784,
            (0.005764, 0.004139),
            (0.353613, 0.262139),
        ),
        (
            "fr2_desk_groundtruth.txt",
            "fr2_desk_ORB.txt",
            2173,
            (0.003490, 0.002750),
            (0.280519, 0.187818),
        ),
    ],
)
def test_evo_reference_values(
    real_data: Path,
    gt: str,
    est: str,
    pairs: int,
    translation: tuple[float, float],
    rotation: tuple[float, float],
) -> None:
    """(rmse, median) from evo 1.38.1 on the associated poses (max difference 0.01 s):
    ``evo_rpe tum GT EST --delta 1 --delta_unit f`` (translation part, metres) and the
    same with ``--pose_relation angle_deg`` (degrees)."""
    folder = real_data / "tum-trajectories"
    gt_times, gt_poses = read_trajectory(folder / gt, ground_truth=True)
    est_times, est_poses = read_trajectory(folder / est)
    i, j = associate_timestamps(est_times, gt_times, 0.01)
    result = relative_pose_error(est_poses[i], gt_poses[j])
    assert result.pairs == pairs
    assert abs(result.translation_rmse - translation[0]) < 1e-6
    assert abs(result.translation_median - translation[1]) < 1e-6
    assert abs(result.rotation_rmse - rotation[0]) < 1e-6
    assert abs(result.rotation_median - rotation[1]) < 1e-6
    assert (
        trajectory_rpe(TimedPoses(gt_times, gt_poses), TimedPoses(est_times, est_poses)) == result
    )
