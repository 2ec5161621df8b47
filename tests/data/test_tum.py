"""TUM RGB-D reader and writer: association, poses, undistortion, resize/crop, bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.transform import ImageTransform
from eslam.data.tum import (
    TUM_CAMERAS,
    TUM_CROP,
    TUM_DEPTH_SCALE,
    TUM_RESIZE,
    TUMSequence,
    associate,
    camera_for,
    nearest,
    read_groundtruth,
)
from eslam.errors import ConfigError, InputError
from eslam.geometry import interpolate_pose
from eslam.synthetic import FPS, Scene, SynthConfig, build_scene, camera_trajectory, render_frame
from eslam.testing.tum import DEPTH_DELAY, TUM_EPOCH, write_tum_sequence
from eslam.types import Frame

FRAMES = 3
SEED = 2


def _scene_and_poses(count: int = FRAMES) -> tuple[Scene, np.ndarray]:
    config = SynthConfig(frames=count, seed=SEED, step_translation=0.02, step_rotation_deg=1.0)
    scene = build_scene(config.scene, config.seed)
    return scene, camera_trajectory(scene, config)


def tum_frames(camera: str, count: int = FRAMES) -> list[Frame]:
    """Exact renderings of the synthetic room by TUM camera ``camera`` (ideal pinhole)."""
    scene, poses = _scene_and_poses(count)
    k = TUM_CAMERAS[camera].intrinsics
    return [
        Frame(i, *render_frame(scene, k, pose), k, pose, i / FPS) for i, pose in enumerate(poses)
    ]


@pytest.fixture(scope="module")
def fr3_frames() -> list[Frame]:
    return tum_frames("fr3")


@pytest.fixture(scope="module")
def fr3_dir(tmp_path_factory: pytest.TempPathFactory, fr3_frames: list[Frame]) -> Path:
    root = tmp_path_factory.mktemp("tum") / "rgbd_dataset_freiburg3_synthetic"
    write_tum_sequence(root, fr3_frames, camera="fr3")
    return root


@pytest.fixture
def sequence_dir(fr3_dir: Path, tmp_path: Path) -> Path:
    """A private copy of the fr3 folder, for tests that break it."""
    return Path(shutil.copytree(fr3_dir, tmp_path / fr3_dir.name))


def _exact_depth(frame: Frame, scene: Scene, mocap_pose: np.ndarray) -> np.ndarray:
    """Depth ray cast exactly at the reader's intrinsics (after resize/crop) and pose."""
    return render_frame(scene, frame.intrinsics, mocap_pose)[1]


# --- round trips ----------------------------------------------------------------------


def test_fr3_round_trip_poses_timestamps_intrinsics(fr3_dir: Path, fr3_frames) -> None:
    sequence = TUMSequence(fr3_dir)
    assert sequence.camera.name == "fr3" and len(sequence) == FRAMES and sequence.dropped == 0
    expected_k = ImageTransform(TUM_RESIZE, TUM_CROP).intrinsics(TUM_CAMERAS["fr3"].intrinsics)
    assert sequence.intrinsics == expected_k
    assert expected_k.size == (496, 368)
    np.testing.assert_allclose(
        sequence.timestamps(), TUM_EPOCH + np.arange(FRAMES) / FPS, rtol=0, atol=1e-6
    )
    # poses: relative to the first frame, and back to the file's world exactly
    gt = sequence.gt_poses()
    assert gt is not None and gt.dtype == np.float64
    np.testing.assert_allclose(gt[0], np.eye(4), atol=1e-15)
    for pose, frame in zip(gt, fr3_frames, strict=True):
        np.testing.assert_allclose(sequence.mocap_from_world @ pose, frame.pose_gt, atol=1e-12)
        relative = np.linalg.inv(fr3_frames[0].pose_gt) @ frame.pose_gt
        np.testing.assert_allclose(pose, relative, atol=1e-12)


@pytest.mark.parametrize("pairing", ["release", "associate"])
def test_depth_stamp_takes_the_depth_time_and_its_pose(
    fr3_dir: Path, fr3_frames, pairing: str
) -> None:
    by_colour = TUMSequence(fr3_dir, DataConfig(format="tum", pairing=pairing))
    by_depth = TUMSequence(fr3_dir, DataConfig(format="tum", pairing=pairing, stamp="depth"))
    assert len(by_depth) == len(by_colour) == FRAMES
    np.testing.assert_allclose(
        by_depth.timestamps(), by_colour.timestamps() + DEPTH_DELAY, rtol=0, atol=1e-6
    )
    # the same images; the pose nearest the depth time (10 ms after the colour's) is the
    # writer's sample a third of the way to the next frame (11.1 ms); the last frame
    # has no later sample and keeps its own
    np.testing.assert_array_equal(by_depth[1].depth, by_colour[1].depth)
    np.testing.assert_array_equal(by_depth[1].rgb, by_colour[1].rgb)
    mocap = by_depth.mocap_from_world @ by_depth.gt_poses()
    for i, frame in enumerate(fr3_frames):
        if i + 1 < FRAMES:
            later = fr3_frames[i + 1].pose_gt
            expected = interpolate_pose(
                torch.from_numpy(frame.pose_gt), torch.from_numpy(later), 1 / 3
            ).numpy()
        else:
            expected = frame.pose_gt
        np.testing.assert_allclose(mocap[i], expected, atol=1e-9)
    assert not np.allclose(mocap[0], fr3_frames[0].pose_gt, atol=1e-4)


def test_fr3_round_trip_depth_colour_and_geometry(fr3_dir: Path, fr3_frames) -> None:
    sequence = TUMSequence(fr3_dir)
    transform = ImageTransform(TUM_RESIZE, TUM_CROP)
    scene, _ = _scene_and_poses()
    for original in fr3_frames:
        frame = sequence[original.index]
        assert frame.rgb.shape == (368, 496, 3) and frame.depth.dtype == np.float32
        assert frame.timestamp == pytest.approx(TUM_EPOCH + original.index / FPS, abs=1e-6)
        # depth: the same resize + crop of the original, to the PNG quantisation
        expected = transform.depth(original.depth)
        assert np.abs(frame.depth - expected).max() <= 0.5 / TUM_DEPTH_SCALE + 1e-6
        colour_error = np.abs(frame.rgb.astype(int) - transform.colour(original.rgb).astype(int))
        assert colour_error.max() <= 1, "PNG colour is lossless"
        # geometry: the reader's intrinsics and pose see the scene where its depth says
        exact = _exact_depth(frame, scene, sequence.mocap_from_world @ frame.pose_gt)
        both = (frame.depth > 0) & (exact > 0)
        error = np.abs(frame.depth - exact)[both]
        # (measured: median 0.6 mm, 90th percentile 1.6 mm: nearest-neighbour resize)
        assert both.mean() > 0.95
        assert np.median(error) < 0.001 and np.percentile(error, 90) < 0.004


def test_open_sequence_by_format_with_selection(fr3_dir: Path) -> None:
    options = DataConfig(format="tum", path=str(fr3_dir), start=1, max_frames=1)
    sequence = open_sequence(options)
    assert len(sequence) == 1
    assert sequence.timestamps()[0] == pytest.approx(TUM_EPOCH + 1 / FPS, abs=1e-6)


def test_options_override_resize_crop_and_depth_scale(fr3_dir: Path, fr3_frames) -> None:
    options = DataConfig(resize=(640, 480), crop=0, depth_scale=2 * TUM_DEPTH_SCALE)
    sequence = TUMSequence(fr3_dir, options)
    assert sequence.intrinsics == TUM_CAMERAS["fr3"].intrinsics
    frame = sequence[1]
    np.testing.assert_allclose(frame.depth, fr3_frames[1].depth / 2, atol=1e-4)


def test_folder_without_groundtruth(fr3_dir: Path, tmp_path: Path, fr3_frames) -> None:
    root = tmp_path / "rgbd_dataset_freiburg3_nogt"
    write_tum_sequence(root, fr3_frames, camera="fr3", with_groundtruth=False)
    assert not (root / "groundtruth.txt").exists()
    sequence = TUMSequence(root)
    assert len(sequence) == FRAMES
    assert sequence.gt_poses() is None and sequence.mocap_from_world is None
    assert sequence[0].pose_gt is None
    np.testing.assert_array_equal(sequence.timestamps(), TUMSequence(fr3_dir).timestamps())


@pytest.mark.parametrize("camera", ["fr1", "fr2"])
def test_distorted_images_are_undistorted(camera: str, tmp_path: Path) -> None:
    frames = tum_frames(camera, count=1)
    root = tmp_path / "distorted"
    write_tum_sequence(root, frames, camera=camera, distort=True)
    native = DataConfig(camera=camera, resize=(640, 480), crop=0)
    frame = TUMSequence(root, native)[0]
    original = frames[0]
    # the written images really are distorted (border pixels moved by several pixels) ...
    written = np.asarray(Image.open(next((root / "depth").iterdir())), dtype=np.float32)
    moved = np.abs(written / TUM_DEPTH_SCALE - original.depth)[20:-20, 20:-20]
    assert np.percentile(moved, 90) > 0.005
    # ... and the reader undoes it: nearest twice may pick a neighbour (measured: 0.05 %)
    inner = (slice(20, -20), slice(20, -20))
    both = (frame.depth[inner] > 0) & (original.depth[inner] > 0)
    error = np.abs(frame.depth[inner] - original.depth[inner])[both]
    assert both.mean() > 0.99
    assert (error <= 0.5 / TUM_DEPTH_SCALE + 1e-6).mean() > 0.99
    colour = np.abs(frame.rgb[inner].astype(int) - original.rgb[inner].astype(int))
    assert colour.mean() < 1.0
    # no depth is blended: every value read is one of the written values (or 0)
    written_values = set(np.unique(written / TUM_DEPTH_SCALE).astype(np.float32).tolist())
    assert set(np.unique(frame.depth).tolist()) <= written_values | {0.0}
    # default resize + crop: the reader's intrinsics and pose see what its depth says
    resized = TUMSequence(root, DataConfig(camera=camera))[0]
    scene, _ = _scene_and_poses(1)
    exact = _exact_depth(resized, scene, original.pose_gt)
    both = (resized.depth > 0) & (exact > 0)
    error = np.abs(resized.depth - exact)[both]
    # measured: median 0.6 mm, 90th percentile 1.7 mm (8 mm and 28 mm without undistortion)
    assert both.mean() > 0.95
    assert np.median(error) < 0.002 and np.percentile(error, 90) < 0.005


def test_distortion_is_not_applied_to_fr3(tmp_path: Path, fr3_frames) -> None:
    root = tmp_path / "fr3"
    write_tum_sequence(root, fr3_frames[:1], camera="fr3", distort=True)  # fr3 has none
    frame = TUMSequence(root, DataConfig(camera="fr3", resize=(640, 480), crop=0))[0]
    assert np.abs(frame.depth - fr3_frames[0].depth).max() <= 0.5 / TUM_DEPTH_SCALE + 1e-6


# --- association (release semantics) ---------------------------------------------------


def test_nearest_matches_argmin() -> None:
    rng = np.random.default_rng(0)
    times = rng.uniform(0, 10, size=200)
    queries = np.concatenate([rng.uniform(-1, 11, size=300), times[:5], [times.min() - 5]])
    expected = [int(np.argmin(np.abs(times - q))) for q in queries]
    np.testing.assert_array_equal(nearest(times, queries), expected)
    # a tie goes to the earlier time, as np.argmin over sorted times does
    assert nearest(np.array([1.0, 2.0]), np.array([1.5]))[0] == 0


def test_associate_drops_unmatched_and_too_close_frames() -> None:
    colour = np.array([0.0, 1 / 30, 0.05, 2 / 30, 3 / 30, 0.5, 1.0])
    depth = np.array([0.01, 1 / 30 + 0.01, 2 / 30 + 0.01, 3 / 30 + 0.01, 0.6, 0.9])
    pairs = associate(colour, depth, None)
    # 0.05 comes 0.017 s after 1/30 (< 1/32 s): dropped; 0.5 and 1.0 have no depth
    # within 0.08 s (0.1 s away): dropped
    np.testing.assert_array_equal(pairs.colour, [0, 1, 3, 4])
    np.testing.assert_array_equal(pairs.depth, [0, 1, 2, 3])
    assert pairs.pose is None
    poses = np.array([0.0, 0.1, 0.2])
    with_poses = associate(colour, depth, poses)
    # 2/30 and 3/30 both take the pose at 0.1; every kept frame has a pose within 0.08 s
    np.testing.assert_array_equal(with_poses.colour, [0, 1, 3, 4])
    np.testing.assert_array_equal(with_poses.pose, [0, 0, 1, 1])
    no_pose_late = associate(colour, depth, np.array([0.0]))
    np.testing.assert_array_equal(no_pose_late.colour, [0, 1, 3])
    # the time difference must be strictly below max_dt (exact binary fractions here)
    assert len(associate(np.array([0.0]), np.array([0.0625]), None, max_dt=0.0625).colour) == 0
    assert len(associate(np.array([0.0]), np.array([0.0625]), None, max_dt=0.0626).colour) == 1


def test_reader_pairs_each_colour_image_with_the_nearest_depth(sequence_dir: Path) -> None:
    # without frame 1's depth, colour 1 (t = 33 ms) takes depth 0 (t = 10 ms, 23 ms away)
    depth_list = sequence_dir / "depth.txt"
    lines, at = _data_line(depth_list, 1)
    del lines[at]
    depth_list.write_text("\n".join(lines) + "\n")
    sequence = TUMSequence(sequence_dir)
    assert len(sequence) == FRAMES and sequence.dropped == 0
    np.testing.assert_array_equal(sequence[1].depth, sequence[0].depth)
    assert not np.array_equal(sequence[2].depth, sequence[0].depth)


def test_reader_drops_a_colour_image_without_depth_in_time(sequence_dir: Path) -> None:
    rgb_list = sequence_dir / "rgb.txt"
    lines, at = _data_line(rgb_list, FRAMES - 1)
    stamp, name = lines[at].split()
    lines[at] = f"{float(stamp) + 1.0:.6f} {name}"  # 1 s after every depth image
    rgb_list.write_text("\n".join(lines) + "\n")
    sequence = TUMSequence(sequence_dir)
    assert len(sequence) == FRAMES - 1 and sequence.dropped == 1
    np.testing.assert_allclose(
        sequence.timestamps(), TUM_EPOCH + np.arange(FRAMES - 1) / FPS, rtol=0, atol=1e-6
    )
    assert DEPTH_DELAY < 0.08


# --- camera -----------------------------------------------------------------------------


def test_camera_from_folder_name_or_option(tmp_path: Path) -> None:
    assert camera_for(tmp_path / "rgbd_dataset_freiburg1_desk", None).name == "fr1"
    assert camera_for(tmp_path / "fr2_xyz", None).name == "fr2"
    assert camera_for(tmp_path / "rgbd_dataset_freiburg1_desk", "fr3").name == "fr3"
    with pytest.raises(ConfigError, match=r"unknown TUM camera data.camera='fr4'"):
        camera_for(tmp_path / "x", "fr4")
    with pytest.raises(ConfigError, match=r"my_scan: cannot tell the TUM camera.*set data.camera"):
        camera_for(tmp_path / "my_scan", None)


def test_undetectable_camera_is_a_config_error(sequence_dir: Path, tmp_path: Path) -> None:
    renamed = sequence_dir.rename(tmp_path / "office")
    with pytest.raises(ConfigError, match=r"set data\.camera to fr1, fr2 or fr3"):
        TUMSequence(renamed)
    assert len(TUMSequence(renamed, DataConfig(camera="fr3"))) == FRAMES


# --- bad input: each error names the file at fault ------------------------------------


def _expect_error(root: Path, file_name: str, message: str) -> None:
    with pytest.raises(InputError, match=message) as caught:
        sequence = TUMSequence(root)
        for index in range(len(sequence)):
            sequence[index]
    assert caught.value.path.name == file_name
    assert file_name in str(caught.value)
    assert "\n" not in str(caught.value)


def _data_line(path: Path, index: int) -> tuple[list[str], int]:
    lines = path.read_text().splitlines()
    positions = [i for i, line in enumerate(lines) if not line.startswith("#")]
    return lines, positions[index]


def test_missing_folder(tmp_path: Path) -> None:
    _expect_error(tmp_path / "rgbd_dataset_freiburg1_nowhere", "rgbd_dataset_freiburg1_nowhere",
                  "folder not found")  # fmt: skip


@pytest.mark.parametrize("name", ["rgb.txt", "depth.txt"])
def test_missing_list(sequence_dir: Path, name: str) -> None:
    (sequence_dir / name).unlink()
    _expect_error(sequence_dir, name, "file not found")


def test_list_line_with_wrong_count(sequence_dir: Path) -> None:
    path = sequence_dir / "rgb.txt"
    lines, at = _data_line(path, 1)
    lines[at] += " extra"
    path.write_text("\n".join(lines) + "\n")
    _expect_error(sequence_dir, "rgb.txt", f"line {at + 1}: expected 'timestamp filename', got 3")


def test_list_timestamp_not_a_number(sequence_dir: Path) -> None:
    path = sequence_dir / "depth.txt"
    lines, at = _data_line(path, 0)
    lines[at] = "soon " + lines[at].split()[1]
    path.write_text("\n".join(lines) + "\n")
    _expect_error(sequence_dir, "depth.txt", f"line {at + 1}: timestamp 'soon' is not a finite")


def test_empty_list(sequence_dir: Path) -> None:
    (sequence_dir / "rgb.txt").write_text("# timestamp filename\n")
    _expect_error(sequence_dir, "rgb.txt", "lists no colour images")


def test_listed_colour_image_missing(sequence_dir: Path) -> None:
    image = sorted((sequence_dir / "rgb").iterdir())[1]
    image.unlink()
    _expect_error(sequence_dir, image.name, "listed in rgb.txt .*but not found")


def test_listed_depth_image_missing(sequence_dir: Path) -> None:
    image = sorted((sequence_dir / "depth").iterdir())[2]
    image.unlink()
    _expect_error(sequence_dir, image.name, "listed in depth.txt .*but not found")


def test_no_colour_image_pairs_with_depth(sequence_dir: Path) -> None:
    path = sequence_dir / "depth.txt"
    lines = path.read_text().splitlines()
    shifted = [
        line if line.startswith("#") else f"{float(line.split()[0]) + 5:.6f} {line.split()[1]}"
        for line in lines
    ]
    path.write_text("\n".join(shifted) + "\n")
    _expect_error(sequence_dir, "rgb.txt", "no colour image has a depth image and a pose")


def test_groundtruth_from_another_recording(sequence_dir: Path) -> None:
    path = sequence_dir / "groundtruth.txt"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(["# ground truth", "100.0 0 0 0 0 0 0 1"]) + "\n")
    assert len(lines) > 3
    _expect_error(sequence_dir, "rgb.txt", "depth image and a pose in groundtruth.txt within")


def _edit_groundtruth(root: Path, index: int, column: int, value: str) -> int:
    path = root / "groundtruth.txt"
    lines, at = _data_line(path, index)
    fields = lines[at].split()
    fields[column] = value
    lines[at] = " ".join(fields)
    path.write_text("\n".join(lines) + "\n")
    return at + 1


def test_groundtruth_non_finite(sequence_dir: Path) -> None:
    line = _edit_groundtruth(sequence_dir, 2, 2, "nan")
    _expect_error(sequence_dir, "groundtruth.txt", f"line {line}: pose has non-finite values")


def test_groundtruth_infinite_quaternion(sequence_dir: Path) -> None:
    line = _edit_groundtruth(sequence_dir, 0, 7, "inf")
    _expect_error(sequence_dir, "groundtruth.txt", f"line {line}: pose has non-finite values")


def test_groundtruth_non_unit_quaternion(sequence_dir: Path) -> None:
    line = _edit_groundtruth(sequence_dir, 1, 4, "0.9")
    _expect_error(sequence_dir, "groundtruth.txt", f"line {line}: quaternion qx qy qz qw has norm")


def test_groundtruth_wrong_field_count(sequence_dir: Path) -> None:
    path = sequence_dir / "groundtruth.txt"
    path.write_text(path.read_text() + "1305031453.0 1 2 3\n")
    count = len(path.read_text().splitlines())
    _expect_error(sequence_dir, "groundtruth.txt", f"line {count}: expected 8 numbers, got 4")


def test_groundtruth_not_numbers(sequence_dir: Path) -> None:
    line = _edit_groundtruth(sequence_dir, 0, 3, "x")
    _expect_error(sequence_dir, "groundtruth.txt", f"line {line}: not a list of numbers")


def test_unreadable_colour_image(sequence_dir: Path) -> None:
    image = sorted((sequence_dir / "rgb").iterdir())[0]
    image.write_bytes(b"not a png")
    _expect_error(sequence_dir, image.name, "unreadable colour image")


def test_depth_of_wrong_size(sequence_dir: Path) -> None:
    image = sorted((sequence_dir / "depth").iterdir())[1]
    Image.fromarray(np.full((480, 320), 5000, dtype=np.uint16)).save(image)
    _expect_error(sequence_dir, image.name, "image is 320x480 but the intrinsics are for 640x480")


def test_depth_in_wrong_units(sequence_dir: Path) -> None:
    image = sorted((sequence_dir / "depth").iterdir())[0]
    raw = np.asarray(Image.open(image), dtype=np.float64)
    Image.fromarray((raw / 100).astype(np.uint16)).save(image)  # 50 units per metre
    _expect_error(sequence_dir, image.name, "median depth is 0.0.* m with depth scale 5000")


def test_writer_refuses_frames_of_another_camera(fr3_frames, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="not those of TUM fr1"):
        write_tum_sequence(tmp_path / "x", fr3_frames[:1], camera="fr1")


# --- real TUM ground truth ------------------------------------------------------------


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("name", "count"),
    [("freiburg1_xyz-groundtruth.txt", 3000), ("fr2_desk_groundtruth.txt", 20957)],
)
def test_real_groundtruth_is_in_the_optical_frame(real_data: Path, name: str, count: int) -> None:
    groundtruth = read_groundtruth(real_data / "tum-trajectories" / name)
    assert len(groundtruth.timestamps) == count
    assert np.median(np.diff(groundtruth.timestamps)) < 0.011  # 100 Hz (fr2/desk 300 Hz)
    rotation = groundtruth.poses[:, :3, :3]
    rigid = np.abs(np.swapaxes(rotation, 1, 2) @ rotation - np.eye(3)).max()
    assert rigid < 1e-12
    # The mocap world has z up (the camera is held ~1.5 m high). In OpenCV optical axes
    # a hand-held camera looking down at a desk has its x axis (image right) level,
    # its y axis (image down) pointing down and its z axis (forward) tilted down: true
    # for every pose of both sequences (OpenGL axes would make y point up, z backward).
    assert np.all(np.abs(rotation[:, 2, 0]) < 0.3)
    assert np.all(rotation[:, 2, 1] < -0.5)
    assert np.all(rotation[:, 2, 2] < 0.0)
    assert 1.0 < float(np.median(groundtruth.poses[:, 2, 3])) < 2.0
