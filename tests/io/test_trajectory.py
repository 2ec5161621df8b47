"""TUM trajectory files: exact round trip, readable errors, format sniffing, real files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.errors import InputError
from eslam.geometry.rotation import so3_exp
from eslam.io.trajectory import (
    read_run_trajectories,
    read_trajectory,
    read_tum_trajectory,
    write_tum_trajectory,
)


def _random_poses(count: int, seed: int = 0) -> np.ndarray:
    """Random rigid poses, the last three rotating by exactly 180 degrees (or nearly)."""
    rng = np.random.default_rng(seed)
    omega = rng.normal(size=(count, 3))
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    omega[-3] = math.pi * axis
    omega[-2] = (math.pi - 1e-9) * axis
    poses = np.tile(np.eye(4), (count, 1, 1))
    poses[:, :3, :3] = so3_exp(torch.from_numpy(omega)).numpy()
    poses[-1, :3, :3] = np.diag([1.0, -1.0, -1.0])  # 180 degrees about x
    poses[:, :3, 3] = rng.normal(scale=3.0, size=(count, 3))
    return poses


def test_tum_round_trip_is_exact(tmp_path: Path) -> None:
    poses = _random_poses(50)
    times = 1305031098.6659 + np.cumsum(np.random.default_rng(1).uniform(0.01, 0.05, 50))
    path = tmp_path / "out" / "trajectory.txt"
    write_tum_trajectory(path, times, poses)
    read_times, read_poses = read_tum_trajectory(path)
    assert read_times.dtype == np.float64 and read_poses.dtype == np.float64
    np.testing.assert_array_equal(read_times, times)
    np.testing.assert_allclose(read_poses, poses, rtol=0, atol=1e-9)
    assert [p.name for p in path.parent.iterdir()] == ["trajectory.txt"]  # no temp files


def test_tum_write_accepts_tensors_and_float32_poses(tmp_path: Path) -> None:
    poses = torch.from_numpy(_random_poses(5)).float()
    write_tum_trajectory(tmp_path / "t.txt", torch.arange(5), poses)
    times, read = read_tum_trajectory(tmp_path / "t.txt")
    np.testing.assert_array_equal(times, np.arange(5.0))
    np.testing.assert_allclose(read, poses.double().numpy(), atol=1e-6)
    rotations = read[:, :3, :3]
    np.testing.assert_allclose(
        rotations @ rotations.transpose(0, 2, 1), np.tile(np.eye(3), (5, 1, 1)), atol=1e-12
    )


def test_tum_write_format(tmp_path: Path) -> None:
    write_tum_trajectory(tmp_path / "t.txt", [0.0, 1.5], np.tile(np.eye(4), (2, 1, 1)))
    lines = (tmp_path / "t.txt").read_text().splitlines()
    assert lines[0].startswith("# timestamp tx ty tz qx qy qz qw")
    assert lines[1:] == ["0.0 0.0 0.0 0.0 0.0 0.0 0.0 1.0", "1.5 0.0 0.0 0.0 0.0 0.0 0.0 1.0"]


@pytest.mark.parametrize(
    ("times", "poses"),
    [
        (np.zeros(3), np.tile(np.eye(4), (2, 1, 1))),
        (np.zeros((3, 1)), np.tile(np.eye(4), (3, 1, 1))),
        (np.zeros(1), np.full((1, 4, 4), np.nan)),
    ],
)
def test_tum_write_rejects_bad_input(tmp_path: Path, times: np.ndarray, poses: np.ndarray) -> None:
    with pytest.raises(ValueError):
        write_tum_trajectory(tmp_path / "t.txt", times, poses)
    assert not (tmp_path / "t.txt").exists()


def test_tum_read_skips_comments_and_normalises_quaternions(tmp_path: Path) -> None:
    path = tmp_path / "t.txt"
    path.write_text("# header\n\n1.0 1 2 3 0 0 0 2\n   \n  # indented comment\n2.0 0 0 0 0 0 3 3\n")
    times, poses = read_tum_trajectory(path)
    np.testing.assert_array_equal(times, [1.0, 2.0])
    np.testing.assert_allclose(poses[0], [[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]])
    np.testing.assert_allclose(poses[1, :3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


@pytest.mark.parametrize(
    ("content", "line", "words"),
    [
        ("0 0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n", 2, "expected 8 numbers"),
        ("# c\n0 0 0 0 0 0 0 1 5\n", 2, "got 9"),
        ("0 0 0 0 x 0 0 1\n", 1, "'x' is not a number"),
        ("0 0 0 0 0 0 0 1\n\n0 nan 0 0 0 0 0 1\n", 3, "non-finite"),
        ("0 0 0 0 0 0 0 inf\n", 1, "non-finite"),
        ("0 0 0 0 0 0 0 0\n", 1, "quaternion qx qy qz qw has norm 0"),
    ],
)
def test_tum_read_errors_name_file_and_line(
    tmp_path: Path, content: str, line: int, words: str
) -> None:
    path = tmp_path / "bad_trajectory.txt"
    path.write_text(content)
    with pytest.raises(InputError) as caught:
        read_tum_trajectory(path)
    message = str(caught.value)
    assert "bad_trajectory.txt" in message and f"line {line}:" in message and words in message


def test_tum_read_missing_or_empty_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"nothere\.txt: not found"):
        read_tum_trajectory(tmp_path / "nothere.txt")
    (tmp_path / "empty.txt").write_text("# only a comment\n")
    with pytest.raises(InputError, match=r"empty\.txt: holds no poses"):
        read_tum_trajectory(tmp_path / "empty.txt")


def test_read_trajectory_sniffs_tum_replica_and_folders(tmp_path: Path) -> None:
    poses = _random_poses(6)
    write_tum_trajectory(tmp_path / "tum.txt", np.linspace(10.0, 11.0, 6), poses)
    times, read = read_trajectory(tmp_path / "tum.txt")
    np.testing.assert_array_equal(times, np.linspace(10.0, 11.0, 6))
    np.testing.assert_allclose(read, poses, atol=1e-9)

    replica = tmp_path / "sequence" / "traj.txt"
    replica.parent.mkdir()
    replica.write_text("".join(" ".join(f"{v:.18e}" for v in p.ravel()) + "\n" for p in poses))
    times, read = read_trajectory(replica)
    np.testing.assert_array_equal(times, np.arange(6.0))
    np.testing.assert_allclose(read, poses, atol=1e-15)
    np.testing.assert_array_equal(read_trajectory(replica.parent)[1], read)

    run = tmp_path / "run"
    write_tum_trajectory(run / "trajectory.txt", np.arange(6.0), poses)
    times, read = read_trajectory(run)
    np.testing.assert_array_equal(times, np.arange(6.0))
    np.testing.assert_allclose(read, poses, atol=1e-9)


def test_read_trajectory_errors(tmp_path: Path) -> None:
    (tmp_path / "kitti.txt").write_text("# c\n" + " ".join(["0"] * 12) + "\n")
    with pytest.raises(InputError, match=r"kitti.txt: line 2: expected 8 or 16 numbers, got 12"):
        read_trajectory(tmp_path / "kitti.txt")
    (tmp_path / "empty_run").mkdir()
    with pytest.raises(InputError, match=r"empty_run: holds no trajectory\.txt"):
        read_trajectory(tmp_path / "empty_run")
    with pytest.raises(InputError, match=r"missing\.txt: not found"):
        read_trajectory(tmp_path / "missing.txt")


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("name", "count", "first", "last"),
    [
        ("freiburg1_xyz-groundtruth.txt", 3000, 1305031098.6659, 1305031128.7555),
        ("freiburg1_xyz-rgbdslam.txt", 788, 1305031102.160407, 1305031128.722976),
        ("fr2_desk_groundtruth.txt", 20957, 1311868163.8697, 1311868263.2342),
        ("fr2_desk_ORB.txt", 2893, 1311868164.363181, 1311868263.185529),
    ],
)
def test_read_real_tum_files(
    real_data: Path, tmp_path: Path, name: str, count: int, first: float, last: float
) -> None:
    path = real_data / "tum-trajectories" / name
    times, poses = read_trajectory(path)
    assert times.shape == (count,) and poses.shape == (count, 4, 4)
    assert times[0] == first and times[-1] == last
    assert np.all(np.diff(times) >= 0)  # fr2/desk repeats one time stamp
    rotations = poses[:, :3, :3]
    np.testing.assert_allclose(
        rotations @ rotations.transpose(0, 2, 1), np.tile(np.eye(3), (count, 1, 1)), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(rotations), 1.0, atol=1e-12)
    np.testing.assert_array_equal(poses[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (count, 1)))
    write_tum_trajectory(tmp_path / name, times, poses)
    again_times, again = read_tum_trajectory(tmp_path / name)
    np.testing.assert_array_equal(again_times, times)
    np.testing.assert_allclose(again, poses, rtol=0, atol=1e-9)


def test_run_folder_ground_truth_and_replica_fallback(tmp_path: Path) -> None:
    poses = _random_poses(5)
    run = tmp_path / "run"
    write_tum_trajectory(run / "trajectory.txt", np.arange(5.0), poses)
    write_tum_trajectory(run / "trajectory_gt.txt", np.arange(5.0), poses[::-1])
    np.testing.assert_allclose(read_trajectory(run)[1], poses, atol=1e-9)
    np.testing.assert_allclose(read_trajectory(run, ground_truth=True)[1], poses[::-1], atol=1e-9)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"empty: holds no trajectory_gt\.txt"):
        read_trajectory(tmp_path / "empty", ground_truth=True)


def test_missing_poses_are_read_as_nan_only_when_allowed(tmp_path: Path) -> None:
    tum = tmp_path / "tum.txt"
    tum.write_text("0 1 2 3 0 0 0 1\n1 nan nan nan nan nan nan nan\n2 0 0 inf 0 0 0 1\n")
    with pytest.raises(InputError, match="line 2: pose has non-finite values"):
        read_trajectory(tum)
    times, poses = read_trajectory(tum, allow_missing=True)
    np.testing.assert_array_equal(times, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(poses[0, :3, 3], [1.0, 2.0, 3.0])
    assert np.isnan(poses[1]).all() and np.isnan(poses[2]).all()
    (tmp_path / "bad_time.txt").write_text("nan 0 0 0 0 0 0 1\n")
    with pytest.raises(InputError, match="line 1: the timestamp is not finite"):
        read_trajectory(tmp_path / "bad_time.txt", allow_missing=True)

    replica = tmp_path / "traj.txt"
    rows = [" ".join(map(str, np.eye(4).ravel())), " ".join(["-inf"] * 16)]
    replica.write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match="non-finite"):
        read_trajectory(replica)
    times, poses = read_trajectory(replica, allow_missing=True)
    np.testing.assert_array_equal(times, [0.0, 1.0])
    np.testing.assert_array_equal(poses[0], np.eye(4))
    assert np.isnan(poses[1]).all()
    replica.write_text(" ".join(["2"] * 16) + "\n")  # finite but not rigid: still an error
    with pytest.raises(InputError, match="not a rigid transform"):
        read_trajectory(replica, allow_missing=True)


def test_a_run_folder_gives_its_estimate_and_ground_truth_row_for_row(tmp_path: Path) -> None:
    poses = _random_poses(5)
    stamps = np.arange(5.0)
    write_tum_trajectory(tmp_path / "trajectory.txt", stamps, poses)
    with pytest.raises(InputError, match=r"trajectory_gt\.txt.*missing.*finished run"):
        read_run_trajectories(tmp_path)
    write_tum_trajectory(tmp_path / "trajectory_gt.txt", stamps, poses)
    lines = (tmp_path / "trajectory_gt.txt").read_text().splitlines()
    row = next(i for i, line in enumerate(lines) if line.startswith("2."))
    lines[row] = "2.0 nan nan nan nan nan nan nan"  # a frame the run could not score
    (tmp_path / "trajectory_gt.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"map\.pt.*missing"):
        read_run_trajectories(tmp_path, "map.pt")
    times, estimated, read_truth = read_run_trajectories(tmp_path)
    np.testing.assert_array_equal(times, stamps)
    np.testing.assert_allclose(estimated, poses, atol=1e-9)
    assert np.isnan(read_truth[2]).all() and np.isfinite(np.delete(read_truth, 2, 0)).all()
