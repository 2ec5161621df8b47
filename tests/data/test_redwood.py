"""Open3D's reconstruction layout (data.format: redwood)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.config import DataConfig
from eslam.data import open_sequence
from eslam.data.redwood import PRIMESENSE
from eslam.errors import InputError
from eslam.testing.recordings import depth_millimetres, write_redwood_folder


def test_a_redwood_folder_reads_back_frames_camera_and_log_trajectory(
    small_frames: list, tmp_path: Path
) -> None:
    root = write_redwood_folder(tmp_path / "scene", small_frames)
    sequence = open_sequence(DataConfig(format="redwood", path=str(root)))
    assert len(sequence) == len(small_frames)
    assert sequence.intrinsics == small_frames[0].intrinsics
    expected = np.array([f.pose_gt for f in small_frames])
    np.testing.assert_array_equal(sequence.gt_poses(), expected)
    np.testing.assert_array_equal(sequence.timestamps(), np.arange(len(small_frames)))
    frame = sequence[3]
    np.testing.assert_array_equal(frame.rgb, small_frames[3].rgb)
    millimetres = depth_millimetres(small_frames[3].depth).astype(np.float32)
    np.testing.assert_array_equal(frame.depth, millimetres / np.float32(1000.0))


def test_without_a_camera_json_the_camera_is_open3ds_primesense(
    small_frames: list, tmp_path: Path
) -> None:
    root = write_redwood_folder(tmp_path / "s", small_frames[:2], camera_json=False)
    sequence = open_sequence(DataConfig(format="redwood", path=str(root)))
    assert sequence.intrinsics == PRIMESENSE and sequence.gt_poses() is not None
    with pytest.raises(InputError, match="image is 64x48 but the intrinsics are for 640x480"):
        sequence[0]


def test_a_log_with_the_wrong_pose_count_or_unequal_images_is_refused(
    small_frames: list, tmp_path: Path
) -> None:
    root = write_redwood_folder(tmp_path / "s", small_frames[:3])
    log = root / "trajectory.log"
    log.write_text("\n".join(log.read_text().splitlines()[:10]) + "\n")
    with pytest.raises(InputError, match="has 2 poses for 3 frames"):
        open_sequence(DataConfig(format="redwood", path=str(root)))
    log.unlink()
    (root / "depth" / "000002.png").unlink()
    with pytest.raises(InputError, match="image/ holds 3 images and depth/ 2"):
        open_sequence(DataConfig(format="redwood", path=str(root)))
