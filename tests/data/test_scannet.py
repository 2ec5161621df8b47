"""ScanNet reader and writer: round trip against the synthetic ground truth, bad input."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.scannet import (
    RELEASE_DEPTH_INTRINSICS,
    SCANNET_CROP,
    ScanNetSequence,
    depth_intrinsics,
)
from eslam.errors import InputError
from eslam.geometry.camera import backproject_depth
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing import write_scannet_sequence
from eslam.types import Frame

WIDTH, HEIGHT = 80, 60
COLOUR_SIZE = (162, 121)
"""ScanNet's 1296x968 colour / 8: colour is written larger than depth, as ScanNet's is."""


def _frames(count: int = 3) -> list[Frame]:
    return list(generate_sequence(SynthConfig(frames=count, width=WIDTH, height=HEIGHT, seed=3)))


def _world_points(frame: Frame) -> np.ndarray:
    """(H, W, 3) world points of every pixel of ``frame`` from its depth, intrinsics, pose."""
    depth = torch.from_numpy(frame.depth).double()
    pose = torch.from_numpy(frame.pose_gt)
    return backproject_depth(depth, frame.intrinsics, pose).numpy()


@pytest.fixture
def scene(tmp_path: Path) -> Path:
    root = tmp_path / "scene0000_00"
    write_scannet_sequence(root, _frames(), colour_size=COLOUR_SIZE)
    return root


def test_round_trip_against_ground_truth(scene: Path) -> None:
    originals = _frames()
    sequence = ScanNetSequence(scene)
    c = SCANNET_CROP
    assert len(sequence) == 3
    assert sequence.intrinsics == originals[0].intrinsics.cropped(c, c, c, c)
    assert sequence.intrinsics.size == (WIDTH - 2 * c, HEIGHT - 2 * c)
    for original in originals:
        frame = sequence[original.index]
        np.testing.assert_array_equal(frame.pose_gt, original.pose_gt)
        expected_depth = original.depth[c:-c, c:-c]
        assert np.abs(frame.depth - expected_depth).max() <= 0.5e-3 + 1e-6
        # Back-projected with the reader's (cropped) intrinsics, every pixel lands on the
        # generator's 3D point: the crop moved the principal point with the image.
        distance = np.linalg.norm(
            _world_points(frame) - _world_points(original)[c:-c, c:-c], axis=-1
        )
        assert distance.max() < 1e-3, f"{distance.max() * 1000:.2f} mm"
        colour_error = np.abs(frame.rgb.astype(int) - original.rgb[c:-c, c:-c].astype(int))
        assert colour_error.mean() < 6.0, "colour resized from 162x121 back to 80x60"
    np.testing.assert_array_equal(sequence.timestamps(), [0.0, 1.0, 2.0])


def test_colour_is_resized_to_depth_size_even_without_crop(scene: Path) -> None:
    sequence = ScanNetSequence(scene, DataConfig(crop=0))
    assert sequence.intrinsics == _frames(1)[0].intrinsics
    assert sequence[0].rgb.shape == (HEIGHT, WIDTH, 3)


def test_lost_tracking_gives_nan_ground_truth_not_an_error(tmp_path: Path) -> None:
    frames = _frames()
    frames[1] = dataclasses.replace(frames[1], pose_gt=None)
    write_scannet_sequence(tmp_path, frames)
    assert "-inf" in (tmp_path / "pose" / "1.txt").read_text()
    sequence = ScanNetSequence(tmp_path)
    poses = sequence.gt_poses()
    assert np.isnan(poses[1]).all()
    assert np.isfinite(poses[[0, 2]]).all()
    assert sequence[1].pose_gt is None
    np.testing.assert_array_equal(sequence[2].pose_gt, frames[2].pose_gt)


def test_frames_sorted_numerically_with_gaps(tmp_path: Path) -> None:
    frames = _frames(12)
    write_scannet_sequence(tmp_path, frames)
    for folder, suffix in (("color", "jpg"), ("depth", "png"), ("pose", "txt")):
        (tmp_path / folder / f"5.{suffix}").unlink()
    sequence = ScanNetSequence(tmp_path)
    numbers = [0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11]
    np.testing.assert_array_equal(sequence.timestamps(), numbers)
    np.testing.assert_array_equal(sequence.gt_poses(), [frames[n].pose_gt for n in numbers])
    assert sequence[5].timestamp == 6.0


def test_open_sequence_registers_scannet(scene: Path) -> None:
    sequence = open_sequence(DataConfig(format="scannet", path=str(scene), max_frames=2))
    assert len(sequence) == 2


def test_release_intrinsics_when_the_file_is_absent(tmp_path: Path) -> None:
    k = depth_intrinsics(tmp_path / "intrinsic_depth.txt", (640, 480))
    assert (k.fx, k.fy, k.cx, k.cy) == RELEASE_DEPTH_INTRINSICS
    assert k.size == (640, 480)


# --- bad input: each error names the file at fault ------------------------------------


def _expect_error(root: Path, file_name: str, message: str) -> None:
    with pytest.raises(InputError, match=message) as caught:
        sequence = ScanNetSequence(root)
        for index in range(len(sequence)):
            sequence[index]
    assert caught.value.path.name == file_name
    assert "\n" not in str(caught.value)


def test_missing_scene_folder(tmp_path: Path) -> None:
    _expect_error(tmp_path / "nowhere", "nowhere", "folder not found")


@pytest.mark.parametrize("folder", ["color", "depth", "pose"])
def test_missing_sub_folder(scene: Path, folder: str) -> None:
    shutil.rmtree(scene / folder)
    _expect_error(scene, folder, "folder not found")


def test_colour_without_depth(scene: Path) -> None:
    (scene / "depth" / "2.png").unlink()
    _expect_error(scene, "2.jpg", r"has no partner depth/2\.\* \(3 vs 2 files\)")


def test_depth_without_colour(scene: Path) -> None:
    (scene / "color" / "0.jpg").unlink()
    _expect_error(scene, "0.png", r"has no partner color/0\.\*")


def test_frame_without_pose(scene: Path) -> None:
    (scene / "pose" / "1.txt").unlink()
    _expect_error(scene, "1.jpg", r"has no partner pose/1\.\*")


def test_finite_non_rigid_pose_is_an_error(scene: Path) -> None:
    path = scene / "pose" / "1.txt"
    pose = np.loadtxt(path)
    pose[:3, :3] *= 1.5
    np.savetxt(path, pose)
    _expect_error(scene, "1.txt", "pose: pose is not a rigid transform")


def test_pose_file_with_wrong_count(scene: Path) -> None:
    (scene / "pose" / "2.txt").write_text("1 0 0 0\n0 1 0 0\n")
    _expect_error(scene, "2.txt", "expected 16 numbers")


def test_colour_intrinsics_in_the_depth_file(scene: Path) -> None:
    # intrinsic_color.txt's K is for the 162x121 colour images: its principal point
    # lies outside the 80x60 depth image.
    shutil.copy(scene / "intrinsic" / "intrinsic_color.txt", scene / "intrinsic_depth.txt")
    shutil.move(scene / "intrinsic_depth.txt", scene / "intrinsic" / "intrinsic_depth.txt")
    _expect_error(scene, "intrinsic_depth.txt", "do not fit the 80x60 depth images")


def test_release_intrinsics_do_not_fit_small_images(scene: Path) -> None:
    (scene / "intrinsic" / "intrinsic_depth.txt").unlink()
    _expect_error(scene, "intrinsic_depth.txt", "fx 577.591 .* do not fit the 80x60")


def test_depth_of_another_size(scene: Path) -> None:
    Image.fromarray(np.full((50, 70), 1000, dtype=np.uint16)).save(scene / "depth" / "1.png")
    _expect_error(scene, "1.png", "image is 70x50 but the intrinsics are for 80x60")


def test_unreadable_colour(scene: Path) -> None:
    (scene / "color" / "2.jpg").write_bytes(b"no jpeg")
    _expect_error(scene, "2.jpg", "unreadable colour image")


def test_wrong_depth_scale_is_named(scene: Path) -> None:
    with pytest.raises(InputError, match=r"depth scale 1000 would give") as caught:
        ScanNetSequence(scene, DataConfig(depth_scale=1.0))[0]
    assert caught.value.path.name == "0.png"


def test_inspect_skips_lost_tracking_in_the_path_length(tmp_path: Path) -> None:
    from eslam.data.inspect import inspect_sequence

    frames = _frames()
    frames[1] = dataclasses.replace(frames[1], pose_gt=None)
    write_scannet_sequence(tmp_path, frames)
    summary = inspect_sequence(ScanNetSequence(tmp_path))
    assert summary.has_ground_truth
    assert np.isfinite(summary.path_length_m) and summary.path_length_m > 0
