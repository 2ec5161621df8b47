"""RealSense input: recordings (the SDK's software device's .db3, a .bag in librealsense's
layout written with rosbags) played back with pyrealsense2; the live camera's errors
without a camera; the import guard."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from eslam.cli import main
from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.bags import recording_format
from eslam.errors import ConfigError, InputError
from eslam.testing.recordings import (
    REALSENSE_DEPTH_UNITS,
    BagLayout,
    write_realsense_bag,
    write_realsense_recording,
    write_ros_bag,
)


@pytest.fixture(scope="module")
def rs():
    """pyrealsense2, or a skip saying why the SDK cannot load here."""
    try:
        import pyrealsense2
    except ImportError as error:
        pytest.skip(f"pyrealsense2 cannot load ({error}): pip install 'eslam[realsense]'")
    return pyrealsense2


@pytest.fixture(scope="module", params=["db3", "bag"])
def recording(
    request: pytest.FixtureRequest, rs, small_frames: list, tmp_path_factory
) -> tuple[Path, np.ndarray]:
    """A .db3 from the SDK's recorder (frame n at (n + 1) * 33.3 ms), or a ROS 1 .bag in
    librealsense's layout written with rosbags (frame n at (n + 1) / 30 s)."""
    folder = tmp_path_factory.mktemp("realsense")
    numbers = np.arange(1, len(small_frames) + 1)
    if request.param == "db3":
        return write_realsense_recording(folder / "rec.db3", small_frames), numbers * 0.0333
    return write_realsense_bag(folder / "rec.bag", small_frames), numbers / 30.0


def _device_depth(depth: np.ndarray) -> np.ndarray:
    """Metres as the device stores them: whole units of REALSENSE_DEPTH_UNITS."""
    return np.round(depth / REALSENSE_DEPTH_UNITS)


def test_a_recording_reads_back_identical_depth_colour_camera_and_scale(
    recording: tuple[Path, np.ndarray], small_frames: list
) -> None:
    recording, times = recording
    assert recording_format(recording) == "realsense"
    sequence = open_sequence(DataConfig(path=str(recording)))  # detected: realsense
    assert type(sequence).__name__ == "RealSenseRecording"
    assert len(sequence) == len(small_frames)
    camera, expected = sequence.intrinsics, small_frames[0].intrinsics
    assert camera.size == expected.size
    mine = (camera.fx, camera.fy, camera.cx, camera.cy)
    theirs = (expected.fx, expected.fy, expected.cx, expected.cy)
    assert mine == pytest.approx(theirs, rel=1e-6)  # the SDK stores float32
    assert sequence.depth_scale == pytest.approx(1.0 / REALSENSE_DEPTH_UNITS, rel=1e-6)
    np.testing.assert_allclose(sequence.timestamps(), times, atol=1e-6)
    assert sequence.gt_poses() is None
    for index in (len(sequence) - 1, 0, 1, 3):  # the last first, then back: a restart
        frame, original = sequence[index], small_frames[index]
        np.testing.assert_array_equal(frame.rgb, original.rgb)
        units = frame.depth * sequence.depth_scale
        np.testing.assert_allclose(units, _device_depth(original.depth), atol=1e-3)
    sequence.close()


def test_depth_of_another_camera_is_aligned_to_colour(
    rs, small_frames: list, tmp_path: Path
) -> None:
    colour = small_frames[0].intrinsics
    path = write_realsense_recording(
        tmp_path / "half.db3", small_frames[:3], depth_camera=colour.scaled(32, 24)
    )
    sequence = open_sequence(DataConfig(format="realsense", path=str(path)))
    assert sequence.intrinsics.size == colour.size
    frame = sequence[1]
    assert frame.depth.shape == (48, 64)
    valid = frame.depth > 0
    assert valid.mean() > 0.9
    error = np.abs(frame.depth[valid] - small_frames[1].depth[valid])
    assert np.median(error) < 0.03  # half-resolution depth resampled, then aligned


def test_a_plain_ros2_db3_is_no_realsense_recording(small_frames: list, tmp_path: Path) -> None:
    folder = write_ros_bag(tmp_path / "bag", small_frames[:2], BagLayout("sqlite3"))
    (database,) = folder.glob("*.db3")
    assert recording_format(database) == "rosbag"
    sequence = open_sequence(DataConfig(path=str(database)))
    assert type(sequence).__name__ == "RosbagSequence" and len(sequence) == 2


def test_without_a_camera_eslam_run_source_fails_in_one_line(
    rs, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    if len(rs.context().query_devices()) > 0:
        pytest.skip("a RealSense camera is attached")
    out = tmp_path / "run"
    assert main(["run", "demo", "--source", "realsense", "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "no RealSense camera found" in error
    assert not out.exists()
    assert main(["run", "demo", "--source", "kinect", "--out", str(out)]) == 2
    assert "--source must be realsense or realsense:SERIAL" in capsys.readouterr().err
    both = ["run", "demo", "--source", "realsense", "--data", str(tmp_path), "--out", str(out)]
    assert main(both) == 2
    assert "exclude each other" in capsys.readouterr().err and not out.exists()


def test_without_pyrealsense2_the_error_names_the_extra_and_libusb(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from eslam.data.realsense import RealSenseRecording

    monkeypatch.setitem(sys.modules, "pyrealsense2", None)  # import fails
    recording = tmp_path / "rec.bag"
    recording.write_bytes(b"#ROSBAG V2.0\n")
    with pytest.raises(ConfigError) as error:
        RealSenseRecording(recording)
    assert 'pip install "eslam[realsense]"' in str(error.value)
    assert "libusb-1.0-0" in str(error.value)
    with pytest.raises(InputError, match="recording not found"):
        RealSenseRecording(tmp_path / "missing.db3")
