"""Replica reader and writer: round trips, the real sequences, and every bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.replica import REPLICA_DEPTH_SCALE, ReplicaSequence, write_replica_sequence
from eslam.errors import ConfigError, InputError
from eslam.geometry.camera import backproject_depth, project_points
from eslam.types import Frame, Intrinsics

INTRINSICS = Intrinsics(width=32, height=24, fx=30.0, fy=30.0, cx=15.5, cy=11.5)


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    pose = np.eye(4)
    pose[:3, :3] = q
    pose[:3, 3] = rng.uniform(-2, 2, size=3)
    return pose


def _frames(count: int, seed: int = 0) -> list[Frame]:
    rng = np.random.default_rng(seed)
    frames = []
    for index in range(count):
        depth = rng.uniform(0.3, 8.0, size=(24, 32)).astype(np.float32)
        depth[rng.random(size=depth.shape) < 0.1] = 0.0
        rgb = np.zeros((24, 32, 3), dtype=np.uint8)
        rgb[..., 0] = np.linspace(0, 255, 32, dtype=np.uint8)[None, :]
        rgb[..., 1] = np.linspace(0, 255, 24, dtype=np.uint8)[:, None]
        rgb[..., 2] = 40 * index
        frames.append(Frame(index, rgb, depth, INTRINSICS, _random_pose(rng), float(index)))
    return frames


@pytest.fixture
def sequence_dir(tmp_path: Path) -> Path:
    root = tmp_path / "seq"
    write_replica_sequence(root, _frames(3))
    return root


def test_round_trip_depth_poses_and_colour(sequence_dir: Path) -> None:
    originals = _frames(3)
    sequence = ReplicaSequence(sequence_dir)
    assert len(sequence) == 3
    assert sequence.intrinsics == INTRINSICS
    assert sequence.depth_scale == REPLICA_DEPTH_SCALE
    for original in originals:
        frame = sequence[original.index]
        assert frame.depth.dtype == np.float32
        assert np.abs(frame.depth - original.depth).max() <= 0.5 / REPLICA_DEPTH_SCALE + 1e-7
        assert np.array_equal(frame.depth == 0, original.depth == 0)
        np.testing.assert_allclose(frame.pose_gt, original.pose_gt, rtol=0, atol=1e-15)
        colour_error = np.abs(frame.rgb.astype(int) - original.rgb.astype(int)).mean()
        assert colour_error < 4.0, "JPEG at quality 95 should keep a smooth gradient"
    np.testing.assert_array_equal(
        sequence.gt_poses()[:, :3, 3], [f.pose_gt[:3, 3] for f in originals]
    )


def test_open_sequence_by_format(sequence_dir: Path) -> None:
    assert len(open_sequence(DataConfig(format="replica", path=str(sequence_dir)))) == 3
    with pytest.raises(ConfigError, match=r"unknown data format 'replicaa'.*replica"):
        open_sequence(DataConfig(format="replicaa", path=str(sequence_dir)))


def test_index_out_of_range(sequence_dir: Path) -> None:
    with pytest.raises(IndexError):
        ReplicaSequence(sequence_dir)[3]


def test_subset_of_frames_takes_poses_by_file_number(tmp_path: Path) -> None:
    root = tmp_path / "seq"
    frames = _frames(4)
    write_replica_sequence(root, frames)
    (root / "results" / "frame000000.jpg").unlink()
    (root / "results" / "depth000000.png").unlink()
    sequence = ReplicaSequence(root)
    assert len(sequence) == 3
    np.testing.assert_allclose(sequence[0].pose_gt, frames[1].pose_gt, atol=1e-15)
    assert sequence[0].timestamp == 1.0


# --- bad input: each error names the file at fault ------------------------------------


def _expect_error(root: Path, file_name: str, message: str) -> None:
    with pytest.raises(InputError, match=message) as caught:
        sequence = ReplicaSequence(root)
        for index in range(len(sequence)):
            sequence[index]
    assert caught.value.path.name == file_name
    assert file_name in str(caught.value)
    assert "\n" not in str(caught.value)


def test_missing_folder(tmp_path: Path) -> None:
    _expect_error(tmp_path / "nowhere", "nowhere", "folder not found")


def test_missing_results_folder(sequence_dir: Path) -> None:
    shutil.rmtree(sequence_dir / "results")
    _expect_error(sequence_dir, "results", "folder not found")


def test_missing_traj(sequence_dir: Path) -> None:
    (sequence_dir / "traj.txt").unlink()
    _expect_error(sequence_dir, "traj.txt", "file not found")


def test_missing_cam_params(sequence_dir: Path) -> None:
    (sequence_dir / "cam_params.json").unlink()
    _expect_error(sequence_dir, "cam_params.json", "file not found")


def test_cam_params_without_field(sequence_dir: Path) -> None:
    (sequence_dir / "cam_params.json").write_text(json.dumps({"camera": {"w": 32, "h": 24}}))
    _expect_error(sequence_dir, "cam_params.json", "missing camera field 'fx'")


def test_cam_params_not_json(sequence_dir: Path) -> None:
    (sequence_dir / "cam_params.json").write_text("{camera: ")
    _expect_error(sequence_dir, "cam_params.json", "not valid JSON")


def test_colour_without_depth(sequence_dir: Path) -> None:
    (sequence_dir / "results" / "depth000001.png").unlink()
    _expect_error(
        sequence_dir, "frame000001.jpg", "no partner depth000001.png: 3 colour vs 2 depth"
    )


def test_depth_without_colour(sequence_dir: Path) -> None:
    (sequence_dir / "results" / "frame000002.jpg").unlink()
    _expect_error(sequence_dir, "depth000002.png", "no partner frame000002.jpg")


def test_fewer_poses_than_frames(sequence_dir: Path) -> None:
    traj = sequence_dir / "traj.txt"
    traj.write_text("\n".join(traj.read_text().splitlines()[:2]) + "\n")
    _expect_error(sequence_dir, "traj.txt", "has 2 poses but the images go up to frame 2")


def test_non_finite_pose(sequence_dir: Path) -> None:
    traj = sequence_dir / "traj.txt"
    lines = traj.read_text().splitlines()
    values = lines[1].split()
    values[3] = "nan"
    lines[1] = " ".join(values)
    traj.write_text("\n".join(lines) + "\n")
    _expect_error(sequence_dir, "traj.txt", "line 2: pose has non-finite values")


def test_non_rigid_pose(sequence_dir: Path) -> None:
    traj = sequence_dir / "traj.txt"
    lines = traj.read_text().splitlines()
    values = [float(v) for v in lines[0].split()]
    values[0] *= 1.5
    lines[0] = " ".join(map(str, values))
    traj.write_text("\n".join(lines) + "\n")
    _expect_error(sequence_dir, "traj.txt", "line 1: pose is not a rigid transform")


def test_pose_line_with_wrong_count(sequence_dir: Path) -> None:
    traj = sequence_dir / "traj.txt"
    traj.write_text(traj.read_text() + "1 0 0\n")
    _expect_error(sequence_dir, "traj.txt", "line 4: expected 16 numbers, got 3")


def test_pose_line_not_numbers(sequence_dir: Path) -> None:
    traj = sequence_dir / "traj.txt"
    traj.write_text("a b c\n")
    _expect_error(sequence_dir, "traj.txt", "line 1: not a list of numbers")


def test_unreadable_colour_image(sequence_dir: Path) -> None:
    (sequence_dir / "results" / "frame000001.jpg").write_bytes(b"not a jpeg at all")
    _expect_error(sequence_dir, "frame000001.jpg", "unreadable colour image")


def test_unreadable_depth_image(sequence_dir: Path) -> None:
    (sequence_dir / "results" / "depth000000.png").write_bytes(b"\x89PNG broken")
    _expect_error(sequence_dir, "depth000000.png", "unreadable depth image")


def test_depth_of_wrong_size(sequence_dir: Path) -> None:
    from PIL import Image

    Image.fromarray(np.zeros((10, 10), dtype=np.uint16)).save(
        sequence_dir / "results" / "depth000002.png"
    )
    _expect_error(
        sequence_dir, "depth000002.png", "image is 10x10 but the intrinsics are for 32x24"
    )


def test_colour_depth_image(sequence_dir: Path) -> None:
    from PIL import Image

    Image.fromarray(np.zeros((24, 32, 3), dtype=np.uint8)).save(
        sequence_dir / "results" / "depth000001.png"
    )
    _expect_error(sequence_dir, "depth000001.png", "depth must be a single-channel integer image")


def test_empty_results(sequence_dir: Path) -> None:
    for path in (sequence_dir / "results").iterdir():
        path.unlink()
    _expect_error(sequence_dir, "results", "holds no frame")


# --- the real Replica sequences ------------------------------------------------------


def _reprojection_error(frame_a: Frame, frame_b: Frame, stride: int = 4) -> tuple[float, float]:
    """Median |depth predicted from frame A - depth observed in B| over A's points seen by B.

    Returns (median error in metres, fraction of A's valid points that land in B).
    """
    depth_a = torch.from_numpy(frame_a.depth).double()
    points = backproject_depth(depth_a, frame_a.intrinsics, torch.from_numpy(frame_a.pose_gt))
    valid = torch.from_numpy(frame_a.valid_depth)
    points = points[::stride, ::stride][valid[::stride, ::stride]]
    uv, z = project_points(points, frame_b.intrinsics, torch.from_numpy(frame_b.pose_gt))
    u, v = uv[:, 0].round().long(), uv[:, 1].round().long()
    k = frame_b.intrinsics
    inside = (z > 0) & (u >= 0) & (u < k.width) & (v >= 0) & (v < k.height)
    observed = torch.from_numpy(frame_b.depth).double()[v[inside], u[inside]]
    seen = observed > 0
    error = (z[inside][seen] - observed[seen]).abs()
    return float(error.median()), float(inside.double().mean())


@pytest.mark.realdata
def test_real_replica_room0_frames_agree(real_data: Path) -> None:
    sequence = ReplicaSequence(real_data / "replica-room0")
    assert len(sequence) == 20
    assert sequence.intrinsics == Intrinsics(1200, 680, 600.0, 600.0, 599.5, 339.5)
    first, later = sequence[0], sequence[19]
    assert 0.5 < float(np.median(first.depth[first.valid_depth])) < 6.0
    error, overlap = _reprojection_error(first, later)
    assert overlap > 0.5
    # Exact synthetic renderings: disagreement is only depth quantisation and pixel rounding.
    assert error < 0.002, f"median reprojection disagreement {error * 1000:.2f} mm"
    # The same poses read in OpenGL axes would put frame 0's points behind camera 19:
    flipped = Frame(
        later.index, later.rgb, later.depth, later.intrinsics,
        later.pose_gt @ np.diag([1.0, -1.0, -1.0, 1.0]), later.timestamp,
    )  # fmt: skip
    assert _reprojection_error(first, flipped)[1] < 0.05


@pytest.mark.realdata
def test_real_replica_office0_reads_subset_with_long_trajectory(real_data: Path) -> None:
    sequence = ReplicaSequence(real_data / "replica-office0")
    assert len(sequence) == 4
    lines = (real_data / "replica-office0" / "traj.txt").read_text().splitlines()
    assert len(lines) == 2000
    expected = np.array([float(v) for v in lines[3].split()]).reshape(4, 4)
    np.testing.assert_allclose(sequence[3].pose_gt, expected, atol=0)
    error, overlap = _reprojection_error(sequence[0], sequence[3])
    assert overlap > 0.5 and error < 0.002
