"""7-Scenes reader and writer: synthetic round trip, pose clean-up, bad input, real data."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.sevenscenes import (
    SEVENSCENES_INTRINSICS,
    SevenScenesSequence,
    rotation_error,
)
from eslam.errors import InputError
from eslam.geometry.camera import backproject_depth, project_points
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing import write_sevenscenes_sequence
from eslam.types import Frame

WIDTH, HEIGHT = 64, 48
RAW = DataConfig(register_colour=False)
"""The synthetic recordings' colour is already registered (and 64x48): read it raw."""


def _frames(count: int = 3) -> list[Frame]:
    return list(generate_sequence(SynthConfig(frames=count, width=WIDTH, height=HEIGHT, seed=5)))


def _world_points(frame: Frame) -> np.ndarray:
    """(H, W, 3) world points of every pixel of ``frame`` from its depth, intrinsics, pose."""
    depth = torch.from_numpy(frame.depth).double()
    return backproject_depth(depth, frame.intrinsics, torch.from_numpy(frame.pose_gt)).numpy()


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    root = tmp_path / "seq-01"
    write_sevenscenes_sequence(root, _frames())
    return root


def _write_pose(path: Path, pose: np.ndarray) -> None:
    path.write_text("\n".join(" ".join(f"{v:.17g}" for v in row) for row in pose) + "\n")


def test_round_trip_against_ground_truth(recording: Path) -> None:
    originals = _frames()
    sequence = SevenScenesSequence(recording, RAW)
    assert len(sequence) == 3
    assert sequence.intrinsics == originals[0].intrinsics
    for original in originals:
        frame = sequence[original.index]
        np.testing.assert_allclose(frame.pose_gt, original.pose_gt, rtol=0, atol=1e-14)
        assert np.abs(frame.depth - original.depth).max() <= 0.5e-3 + 1e-6
        distance = np.linalg.norm(_world_points(frame) - _world_points(original), axis=-1)
        assert distance.max() < 1e-3, f"{distance.max() * 1000:.2f} mm"
        assert np.abs(frame.rgb.astype(int) - original.rgb.astype(int)).mean() < 4.0
    np.testing.assert_array_equal(sequence.timestamps(), [0.0, 1.0, 2.0])


def test_crop_option_moves_the_principal_point(recording: Path) -> None:
    original = _frames(1)[0]
    frame = SevenScenesSequence(recording, DataConfig(crop=4, register_colour=False))[0]
    assert frame.intrinsics == original.intrinsics.cropped(4, 4, 4, 4)
    distance = np.linalg.norm(_world_points(frame) - _world_points(original)[4:-4, 4:-4], axis=-1)
    assert distance.max() < 1e-3


def test_65535_is_invalid_depth(recording: Path) -> None:
    path = recording / "frame-000001.depth.png"
    raw = np.asarray(Image.open(path)).copy()
    raw[:5, :7] = 65535
    Image.fromarray(raw).save(path)
    frame = SevenScenesSequence(recording, RAW)[1]
    assert np.all(frame.depth[:5, :7] == 0)
    assert frame.valid_depth[5:, 7:].all()


def test_nearly_orthonormal_pose_is_made_orthonormal(recording: Path) -> None:
    original = _frames()[2].pose_gt
    noisy = original.copy()
    noisy[:3, :3] += np.random.default_rng(0).uniform(-4e-4, 4e-4, size=(3, 3))
    assert rotation_error(noisy[:3, :3]) > 1e-4
    _write_pose(recording / "frame-000002.pose.txt", noisy)
    pose = SevenScenesSequence(recording, RAW).gt_poses()[2]
    assert rotation_error(pose[:3, :3]) < 1e-12
    np.testing.assert_allclose(pose[:3, :3], original[:3, :3], atol=1e-3)
    np.testing.assert_array_equal(pose[:3, 3], original[:3, 3])


def test_intrinsics_from_the_parent_folder(tmp_path: Path, recording: Path) -> None:
    shutil.move(recording / "camera-intrinsics.txt", tmp_path / "camera-intrinsics.txt")
    assert SevenScenesSequence(recording, RAW).intrinsics == _frames(1)[0].intrinsics


def test_published_intrinsics_without_a_file(tmp_path: Path) -> None:
    # The official release ships no intrinsics: 640x480 images read with 585/320/240.
    frames = [
        Frame(0, np.zeros((480, 640, 3), np.uint8), np.full((480, 640), 2.0, np.float32),
              SEVENSCENES_INTRINSICS, np.eye(4))
    ]  # fmt: skip
    write_sevenscenes_sequence(tmp_path, frames)
    (tmp_path / "camera-intrinsics.txt").unlink()
    sequence = SevenScenesSequence(tmp_path)
    assert sequence.intrinsics == SEVENSCENES_INTRINSICS
    assert float(sequence[0].depth.mean()) == pytest.approx(2.0)


def test_open_sequence_registers_sevenscenes(recording: Path) -> None:
    sequence = open_sequence(
        DataConfig(format="sevenscenes", path=str(recording), stride=2, register_colour=False)
    )
    assert len(sequence) == 2


# --- bad input: each error names the file at fault ------------------------------------


def _expect_error(root: Path, file_name: str, message: str) -> None:
    with pytest.raises(InputError, match=message) as caught:
        sequence = SevenScenesSequence(root, RAW)
        for index in range(len(sequence)):
            sequence[index]
    assert caught.value.path.name == file_name
    assert "\n" not in str(caught.value)


def test_missing_folder(tmp_path: Path) -> None:
    _expect_error(tmp_path / "nowhere", "nowhere", "folder not found")


def test_scene_folder_of_recordings_is_refused_with_advice(tmp_path: Path) -> None:
    write_sevenscenes_sequence(tmp_path / "seq-01", _frames(1))
    write_sevenscenes_sequence(tmp_path / "seq-02", _frames(1))
    _expect_error(tmp_path, tmp_path.name, r"holds recordings seq-01, seq-02 .*pass one recording")


def test_empty_folder(tmp_path: Path) -> None:
    _expect_error(tmp_path, tmp_path.name, "holds no frame-XXXXXX")


def test_colour_without_depth(recording: Path) -> None:
    (recording / "frame-000001.depth.png").unlink()
    _expect_error(
        recording, "frame-000001.color.jpg", r"no partner frame-000001.depth.png \(3 color vs 2"
    )


def test_depth_without_colour(recording: Path) -> None:
    (recording / "frame-000000.color.jpg").unlink()
    _expect_error(recording, "frame-000000.depth.png", "no partner frame-000000.color.png")


def test_frame_without_pose(recording: Path) -> None:
    (recording / "frame-000002.pose.txt").unlink()
    _expect_error(recording, "frame-000002.color.jpg", "no partner frame-000002.pose.txt")


def test_grossly_non_rigid_pose(recording: Path) -> None:
    pose = _frames()[1].pose_gt.copy()
    pose[:3, :3] *= 1.05
    _write_pose(recording / "frame-000001.pose.txt", pose)
    _expect_error(recording, "frame-000001.pose.txt", "pose is not a rigid transform")


def test_reflection_is_not_a_rotation(recording: Path) -> None:
    pose = _frames()[1].pose_gt.copy()
    pose[:3, 0] *= -1
    _write_pose(recording / "frame-000001.pose.txt", pose)
    _expect_error(recording, "frame-000001.pose.txt", "pose is not a rigid transform")


def test_non_finite_pose(recording: Path) -> None:
    pose = _frames()[0].pose_gt.copy()
    pose[0, 3] = np.inf
    _write_pose(recording / "frame-000000.pose.txt", pose)
    _expect_error(recording, "frame-000000.pose.txt", "pose has non-finite values")


def test_pose_with_wrong_count(recording: Path) -> None:
    (recording / "frame-000000.pose.txt").write_text("1 0 0\n")
    _expect_error(recording, "frame-000000.pose.txt", "expected 16 numbers")


def test_bad_intrinsics_file(recording: Path) -> None:
    (recording / "camera-intrinsics.txt").write_text("585 0 320\n0 585 240\n")
    _expect_error(recording, "camera-intrinsics.txt", "expected 9 numbers")


def test_intrinsics_for_another_image_size(recording: Path) -> None:
    (recording / "camera-intrinsics.txt").write_text("585 0 320\n0 585 240\n0 0 1\n")
    _expect_error(recording, "camera-intrinsics.txt", "do not fit the 64x48 depth images")


def test_published_intrinsics_do_not_fit_other_images(recording: Path) -> None:
    (recording / "camera-intrinsics.txt").unlink()
    _expect_error(
        recording, "frame-000000.color.jpg", "image is 64x48 but the intrinsics are for 640x480"
    )


def test_unreadable_depth(recording: Path) -> None:
    (recording / "frame-000002.depth.png").write_bytes(b"\x89PNG broken")
    _expect_error(recording, "frame-000002.depth.png", "unreadable")


def test_depth_in_wrong_units(recording: Path) -> None:
    with pytest.raises(InputError, match="depth scale 1000 would give") as caught:
        SevenScenesSequence(recording, DataConfig(depth_scale=5.0, register_colour=False))[0]
    assert caught.value.path.name == "frame-000000.depth.png"


# --- the real redkitchen recording -----------------------------------------------------


def _reprojection(frame_a: Frame, frame_b: Frame) -> tuple[np.ndarray, float]:
    """|depth predicted from A - depth observed in B| where both are valid, and A's overlap."""
    points = _world_points(frame_a)[frame_a.valid_depth]
    uv, z = project_points(
        torch.from_numpy(points), frame_b.intrinsics, torch.from_numpy(frame_b.pose_gt)
    )
    u, v = uv[:, 0].round().long().numpy(), uv[:, 1].round().long().numpy()
    k = frame_b.intrinsics
    inside = (z.numpy() > 0) & (u >= 0) & (u < k.width) & (v >= 0) & (v < k.height)
    observed = frame_b.depth[v[inside], u[inside]]
    seen = observed > 0
    return np.abs(z.numpy()[inside][seen] - observed[seen]), float(inside.mean())


@pytest.mark.realdata
def test_real_redkitchen(real_data: Path) -> None:
    sequence = SevenScenesSequence(real_data / "7scenes-redkitchen")
    assert len(sequence) == 400
    assert sequence.intrinsics == SEVENSCENES_INTRINSICS
    poses = sequence.gt_poses()
    rotations = torch.from_numpy(poses[:, :3, :3])
    eye = torch.eye(3, dtype=torch.float64)
    assert float((rotations.transpose(1, 2) @ rotations - eye).abs().max()) < 1e-12
    # Frame 33 holds 46 raw 65535 pixels: none survives as a 65.535 m depth.
    frame_33 = sequence[33]
    assert float(frame_33.depth.max()) < 10.0
    first, later = sequence[0], sequence[10]
    error, overlap = _reprojection(first, later)
    assert overlap > 0.8
    median = float(np.median(error))
    # KinectFusion ground truth (a few mm), Kinect v1 depth noise and pixel rounding:
    # measured 4.4 mm median (90th percentile 18 mm) over 99 % of frame 0's points.
    assert median < 0.01, f"median disagreement {median * 1000:.1f} mm"
    # The same depth with poses in OpenGL axes would not agree at all.
    flipped = Frame(
        later.index, later.rgb, later.depth, later.intrinsics,
        later.pose_gt @ np.diag([1.0, -1.0, -1.0, 1.0]), later.timestamp,
    )  # fmt: skip
    assert _reprojection(first, flipped)[1] < 0.05
