"""ROS bags (data.format: rosbag): bags the tests write with rosbags, read back exactly."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from eslam.config import DataConfig, TopicsConfig
from eslam.data import open_sequence
from eslam.data.bags import effective_format, recording_format
from eslam.data.ros_messages import camera_model
from eslam.data.rosbag import RosbagSequence, pair_by_stamp
from eslam.data.undistort import PlumbBob, Undistorter
from eslam.errors import InputError
from eslam.testing.recordings import BagLayout, depth_millimetres, frame_stamp_ns, write_ros_bag

CASES = {
    "ros1-posestamped-bgr8-padded": (
        "rec.bag",
        BagLayout("ros1", "bgr8", pose_topic="/gt", row_padding=3),
        TopicsConfig(pose="/gt"),
    ),
    "sqlite3-tf-rgba8": (
        "rec2",
        BagLayout("sqlite3", "rgba8", "mono16", pose_topic="/tf", pose_type="TFMessage"),
        TopicsConfig(pose="/tf", pose_frames=("world", "camera")),
    ),
    "mcap-odometry-bigendian": (
        "rec3",
        BagLayout("mcap", "bgra8", pose_topic="/odom", pose_type="Odometry", big_endian=True),
        TopicsConfig(pose="/odom"),
    ),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bags_read_back_identical_frames_camera_stamps_and_poses(
    case: str, small_frames: list, tmp_path: Path
) -> None:
    name, layout, topics = CASES[case]
    path = write_ros_bag(tmp_path / name, small_frames, layout)
    # the format is detected from the file: the default data.format is replica
    sequence = open_sequence(DataConfig(path=str(path), topics=topics))
    assert isinstance(sequence, RosbagSequence) and len(sequence) == len(small_frames)
    assert sequence.intrinsics == small_frames[0].intrinsics
    assert sequence.depth_scale == 1000.0
    stamps = np.array([frame_stamp_ns(i) for i in range(len(small_frames))]) / 1e9
    np.testing.assert_array_equal(sequence.timestamps(), stamps)
    expected_poses = np.array([f.pose_gt for f in small_frames])
    np.testing.assert_allclose(sequence.gt_poses(), expected_poses, atol=1e-12)
    for index in (len(sequence) - 1, 0, 2):  # the last first, as the preflight reads
        frame, original = sequence[index], small_frames[index]
        np.testing.assert_array_equal(frame.rgb, original.rgb)
        millimetres = depth_millimetres(original.depth).astype(np.float32)
        np.testing.assert_array_equal(frame.depth, millimetres / np.float32(1000.0))
        assert frame.timestamp == stamps[index]
    sequence.close()


def test_32fc1_depth_is_metres_and_nan_is_no_depth(small_frames: list, tmp_path: Path) -> None:
    holed = small_frames[1].depth.copy()
    holed[:10, :10] = 0.0  # written as NaN
    frames = [small_frames[0], dataclasses.replace(small_frames[1], depth=holed)]
    layout = BagLayout("ros1", depth_encoding="32FC1", big_endian=True)
    sequence = RosbagSequence(write_ros_bag(tmp_path / "float.bag", frames, layout))
    assert sequence.depth_scale == 1.0 and sequence.gt_poses() is None
    np.testing.assert_array_equal(sequence[1].depth, holed)


def test_colour_and_depth_are_paired_by_stamp_not_arrival(
    small_frames: list, tmp_path: Path
) -> None:
    """Depth stamped 5 ms after colour (and written before it) still pairs frame by frame."""
    layout = BagLayout("mcap", depth_offset_ns=5_000_000)
    sequence = RosbagSequence(write_ros_bag(tmp_path / "offset", small_frames, layout))
    assert len(sequence) == len(small_frames)
    for index in (0, 3):
        expected = depth_millimetres(small_frames[index].depth) / np.float32(1000.0)
        np.testing.assert_array_equal(sequence[index].depth, expected.astype(np.float32))


def test_pairing_is_mutual_nearest_within_the_tolerance_and_drops_the_unpaired() -> None:
    colour = np.array([0, 100, 200, 300, 1000])
    depth = np.array([2, 98, 130, 310])
    assert pair_by_stamp(colour, depth, 20) == [(0, 0), (1, 1), (3, 3)]
    assert pair_by_stamp(colour, np.array([], dtype=np.int64), 20) == []


def test_topics_are_auto_picked_or_named_and_errors_list_the_topics(
    small_frames: list, tmp_path: Path
) -> None:
    own = ("/cam/rgb", "/cam/depth", "/cam/info")
    path = write_ros_bag(tmp_path / "own", small_frames[:2], BagLayout("sqlite3", topics=own))
    sequence = RosbagSequence(path)
    assert sequence.topics == {"colour": own[0], "depth": own[1], "camera_info": own[2]}
    with pytest.raises(InputError) as missing:
        RosbagSequence(path, DataConfig(topics=TopicsConfig(depth="/camera/depth")))
    message = str(missing.value)
    assert "no topic /camera/depth" in message and "/cam/rgb (sensor_msgs/Image, colour)" in message
    assert "\n" not in message
    ambiguous = write_ros_bag(
        tmp_path / "two.bag", small_frames[:2], BagLayout(topics=own, extra_colour_topics=("/b",))
    )
    with pytest.raises(InputError, match=r"2 colour sensor_msgs/Image topics .*/b \(") as error:
        RosbagSequence(ambiguous)
    assert "data.topics.colour" in str(error.value)
    chosen = RosbagSequence(ambiguous, DataConfig(topics=TopicsConfig(colour="/b")))
    np.testing.assert_array_equal(chosen[1].rgb, small_frames[1].rgb)
    with pytest.raises(InputError, match="is no colour sensor_msgs/Image"):
        RosbagSequence(ambiguous, DataConfig(topics=TopicsConfig(colour=own[1])))


def test_a_distorted_camera_is_undistorted(small_frames: list, tmp_path: Path) -> None:
    distortion = (0.05, -0.01, 0.001, 0.0, 0.0)
    layout = BagLayout("ros1", distortion=distortion)
    sequence = RosbagSequence(write_ros_bag(tmp_path / "lens.bag", small_frames[:2], layout))
    camera = small_frames[0].intrinsics
    rgb, depth = Undistorter(camera, PlumbBob(*distortion)).images(
        small_frames[0].rgb, depth_millimetres(small_frames[0].depth) / np.float32(1000.0)
    )
    frame = sequence[0]
    np.testing.assert_array_equal(frame.rgb, rgb)
    np.testing.assert_array_equal(frame.depth, depth)
    assert not np.array_equal(frame.rgb, small_frames[0].rgb)


def test_distortion_eslam_cannot_undo_is_refused() -> None:
    info = SimpleNamespace(
        width=64,
        height=48,
        k=[50, 0, 32, 0, 50, 24, 0, 0, 1],
        d=[0.1, 0, 0, 0],
        distortion_model="equidistant",
    )
    with pytest.raises(InputError, match=r"equidistant.*cannot be undone"):
        camera_model(info, "bag")
    info.distortion_model, info.d = "equidistant", [0.0, 0.0, 0.0, 0.0]
    assert camera_model(info, "bag").distortion is None


def test_no_pairs_and_non_bags_are_one_line_errors(small_frames: list, tmp_path: Path) -> None:
    far = BagLayout("mcap", depth_offset_ns=100_000_000)
    with pytest.raises(InputError, match=r"no colour image .* within 20 ms of its stamp"):
        RosbagSequence(write_ros_bag(tmp_path / "far", small_frames[:2], far))
    text = tmp_path / "notes.bag"
    text.write_text("not a bag")
    with pytest.raises(InputError, match="not a readable ROS bag"):
        RosbagSequence(text)
    assert recording_format(tmp_path) is None
    assert effective_format("replica", tmp_path) == "replica"
    assert effective_format("rosbag", tmp_path / "far") == "rosbag"
