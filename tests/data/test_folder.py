"""Plain-folder reader and writer: both pose formats, no poses, stems, bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.folder import FolderSequence
from eslam.errors import InputError
from eslam.geometry.camera import backproject_depth
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing import write_folder_sequence
from eslam.types import Frame

WIDTH, HEIGHT = 48, 36
DEPTH_SCALE = 5000.0


def _frames(count: int = 3) -> list[Frame]:
    return list(generate_sequence(SynthConfig(frames=count, width=WIDTH, height=HEIGHT, seed=7)))


def _world_points(frame: Frame) -> np.ndarray:
    """(H, W, 3) world points of every pixel of ``frame`` from its depth, intrinsics, pose."""
    depth = torch.from_numpy(frame.depth).double()
    return backproject_depth(depth, frame.intrinsics, torch.from_numpy(frame.pose_gt)).numpy()


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    root = tmp_path / "capture"
    write_folder_sequence(root, _frames(), depth_scale=DEPTH_SCALE, pose_format="tum")
    return root


def test_round_trip_with_tum_poses(folder: Path) -> None:
    originals = _frames()
    sequence = FolderSequence(folder)
    assert len(sequence) == 3
    assert sequence.intrinsics == originals[0].intrinsics
    assert sequence.depth_scale == DEPTH_SCALE
    for original in originals:
        frame = sequence[original.index]
        # Through a quaternion and 17 significant digits: exact to rounding.
        np.testing.assert_allclose(frame.pose_gt, original.pose_gt, rtol=0, atol=1e-12)
        assert np.abs(frame.depth - original.depth).max() <= 0.5 / DEPTH_SCALE + 1e-6
        np.testing.assert_array_equal(frame.rgb, original.rgb)  # PNG is lossless
        distance = np.linalg.norm(_world_points(frame) - _world_points(original), axis=-1)
        assert distance.max() < 1e-3
    np.testing.assert_array_equal(sequence.timestamps(), [0.0, 1.0, 2.0])


def test_round_trip_with_matrix_poses(tmp_path: Path) -> None:
    originals = _frames()
    write_folder_sequence(tmp_path, originals, pose_format="matrix")
    poses = FolderSequence(tmp_path).gt_poses()
    np.testing.assert_array_equal(poses, [f.pose_gt for f in originals])


def test_without_poses(tmp_path: Path) -> None:
    write_folder_sequence(tmp_path, _frames(), pose_format=None)
    sequence = FolderSequence(tmp_path)
    assert sequence.gt_poses() is None
    assert sequence[0].pose_gt is None
    assert len(sequence) == 3


def test_frame_without_a_tum_line_has_nan_ground_truth(folder: Path) -> None:
    path = folder / "poses.txt"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(line for line in lines if not line.startswith("1 ")) + "\n")
    sequence = FolderSequence(folder)
    assert np.isnan(sequence.gt_poses()[1]).all()
    assert np.isfinite(sequence.gt_poses()[[0, 2]]).all()
    assert sequence[1].pose_gt is None


def test_timestamp_stems_and_crop(folder: Path) -> None:
    originals = _frames()
    stamps = ["1305031102.175304", "1305031102.211214", "1305031102.243211"]
    for index, stamp in enumerate(stamps):
        for sub in ("color", "depth"):
            (folder / sub / f"{index:06d}.png").rename(folder / sub / f"{stamp}.png")
    path = folder / "poses.txt"
    lines = [line.split() for line in path.read_text().splitlines()[1:]]
    # Lines in a different order than the frames: matched by timestamp, not position.
    path.write_text("".join(f"{stamps[int(v[0])]} {' '.join(v[1:])}\n" for v in lines[::-1]))
    sequence = FolderSequence(folder, DataConfig(crop=3))
    np.testing.assert_array_equal(sequence.timestamps(), [float(s) for s in stamps])
    assert sequence.intrinsics == originals[0].intrinsics.cropped(3, 3, 3, 3)
    frame = sequence[2]
    np.testing.assert_allclose(frame.pose_gt, originals[2].pose_gt, atol=1e-12)
    distance = np.linalg.norm(
        _world_points(frame) - _world_points(originals[2])[3:-3, 3:-3], axis=-1
    )
    assert distance.max() < 1e-3


def test_name_stems_are_ordered_by_name(tmp_path: Path) -> None:
    originals = _frames()
    write_folder_sequence(tmp_path, originals, pose_format="matrix")
    for index, name in enumerate(["a_first", "b_second", "c_third"]):
        for sub in ("color", "depth"):
            (tmp_path / sub / f"{index:06d}.png").rename(tmp_path / sub / f"{name}.png")
    sequence = FolderSequence(tmp_path)
    np.testing.assert_array_equal(sequence.timestamps(), [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(sequence[1].pose_gt, originals[1].pose_gt)
    np.testing.assert_array_equal(sequence[1].rgb, originals[1].rgb)


def test_zero_distortion_is_accepted(folder: Path) -> None:
    _edit_intrinsics(folder, distortion=[0.0, 0.0, 0.0, 0.0, 0.0])
    assert len(FolderSequence(folder)) == 3


def test_open_sequence_registers_folder(folder: Path) -> None:
    assert len(open_sequence(DataConfig(format="folder", path=str(folder), start=1))) == 2


# --- bad input: each error names the file at fault ------------------------------------


def _edit_intrinsics(root: Path, **changes: object) -> None:
    path = root / "intrinsics.yaml"
    data = yaml.safe_load(path.read_text())
    data.update(changes)
    data = {key: value for key, value in data.items() if value is not None}
    path.write_text(yaml.safe_dump(data))


def _expect_error(root: Path, file_name: str, message: str) -> None:
    with pytest.raises(InputError, match=message) as caught:
        sequence = FolderSequence(root)
        for index in range(len(sequence)):
            sequence[index]
    assert caught.value.path.name == file_name
    assert "\n" not in str(caught.value)


def test_missing_folder(tmp_path: Path) -> None:
    _expect_error(tmp_path / "nowhere", "nowhere", "folder not found")


@pytest.mark.parametrize("sub", ["color", "depth"])
def test_missing_image_folder(folder: Path, sub: str) -> None:
    shutil.rmtree(folder / sub)
    _expect_error(folder, sub, "folder not found")


def test_missing_intrinsics(folder: Path) -> None:
    (folder / "intrinsics.yaml").unlink()
    _expect_error(folder, "intrinsics.yaml", "file not found")


def test_intrinsics_missing_a_key(folder: Path) -> None:
    _edit_intrinsics(folder, fy=None, depth_scale=None)
    _expect_error(folder, "intrinsics.yaml", "missing fy, depth_scale")


def test_intrinsics_unknown_key(folder: Path) -> None:
    _edit_intrinsics(folder, k1=0.1)
    _expect_error(folder, "intrinsics.yaml", "unknown key")


def test_intrinsics_not_yaml(folder: Path) -> None:
    (folder / "intrinsics.yaml").write_text("width: [64\n")
    _expect_error(folder, "intrinsics.yaml", "not valid YAML")


def test_intrinsics_not_numbers(folder: Path) -> None:
    _edit_intrinsics(folder, fx="wide")
    _expect_error(folder, "intrinsics.yaml", "invalid camera parameters")


def test_non_zero_distortion_says_undistort_first(folder: Path) -> None:
    _edit_intrinsics(folder, distortion=[0.1, -0.2, 0.0, 0.0, 0.0])
    _expect_error(folder, "intrinsics.yaml", r"non-zero distortion .*undistort the images first")


def test_intrinsics_for_another_size(folder: Path) -> None:
    _edit_intrinsics(folder, width=640, height=480)
    _expect_error(folder, "000000.png", "image is 48x36 but the intrinsics are for 640x480")


def test_colour_without_depth(folder: Path) -> None:
    (folder / "depth" / "000001.png").unlink()
    _expect_error(folder, "000001.png", r"no partner depth/000001\.\* \(3 colour vs 2 depth")


def test_depth_without_colour(folder: Path) -> None:
    (folder / "color" / "000002.png").unlink()
    _expect_error(folder, "000002.png", r"no partner color/000002\.\*")


def test_two_colour_images_with_one_stem(folder: Path) -> None:
    shutil.copy(folder / "color" / "000000.png", folder / "color" / "000000.jpg")
    _expect_error(folder, "000000.png", "has the same stem as 000000.jpg")


def test_tum_lines_that_match_no_frame(folder: Path) -> None:
    (folder / "poses.txt").write_text("17.5 0 0 0 0 0 0 1\n")
    _expect_error(folder, "poses.txt", "no line's timestamp matches a frame stem")


def test_tum_lines_need_numeric_stems(folder: Path) -> None:
    for sub in ("color", "depth"):
        (folder / sub / "000001.png").rename(folder / sub / "x.png")
    _expect_error(folder, "poses.txt", "timestamped pose lines need image files named by number")


def test_matrix_count_is_not_frame_count(tmp_path: Path) -> None:
    write_folder_sequence(tmp_path, _frames(), pose_format="matrix")
    (tmp_path / "color" / "000002.png").unlink()
    (tmp_path / "depth" / "000002.png").unlink()
    _expect_error(tmp_path, "poses.txt", "has 3 4x4 poses for 2 frames")


def test_non_rigid_matrix(tmp_path: Path) -> None:
    frames = _frames()
    write_folder_sequence(tmp_path, frames, pose_format="matrix")
    pose = frames[1].pose_gt.copy()
    pose[:3, :3] *= 1.1
    lines = (tmp_path / "poses.txt").read_text().splitlines()
    lines[1] = " ".join(f"{v:.17g}" for v in pose.reshape(-1))
    (tmp_path / "poses.txt").write_text("\n".join(lines) + "\n")
    _expect_error(tmp_path, "poses.txt", "line 2: pose is not a rigid transform")


def test_mixed_line_lengths(folder: Path) -> None:
    path = folder / "poses.txt"
    path.write_text(path.read_text() + " ".join(["0"] * 16) + "\n")
    _expect_error(folder, "poses.txt", "line 5: expected 8 numbers, got 16")


def test_zero_quaternion(folder: Path) -> None:
    (folder / "poses.txt").write_text("0 1 2 3 0 0 0 0\n")
    _expect_error(folder, "poses.txt", "line 1: quaternion .* is not a rotation")


def test_non_finite_tum_line(folder: Path) -> None:
    (folder / "poses.txt").write_text("0 nan 2 3 0 0 0 1\n")
    _expect_error(folder, "poses.txt", "line 1: pose has non-finite values")


def test_poses_not_numbers(folder: Path) -> None:
    (folder / "poses.txt").write_text("# header\nzero one two\n")
    _expect_error(folder, "poses.txt", "line 2: not a list of numbers")


def test_depth_scale_option_overrides_the_file(folder: Path) -> None:
    with pytest.raises(InputError, match="depth scale 5000 would give") as caught:
        FolderSequence(folder, DataConfig(depth_scale=100.0))[0]
    assert caught.value.path.name == "000000.png"
