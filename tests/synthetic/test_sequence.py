"""The in-memory synthetic sequence gives the frames `eslam synth` writes and the reader reads."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from eslam.data.base import RGBDSequence
from eslam.data.replica import REPLICA_DEPTH_SCALE, ReplicaSequence
from eslam.synthetic import (
    SynthConfig,
    SyntheticSequence,
    generate_sequence,
    write_synthetic_sequence,
)

CONFIG = SynthConfig(frames=4, width=80, height=60, seed=3, depth_noise=True, missing_depth=True)


def _jpeg(rgb: np.ndarray) -> np.ndarray:
    """``rgb`` after the Replica writer's JPEG (quality 95) and back."""
    buffer = io.BytesIO()
    Image.fromarray(rgb).save(buffer, format="JPEG", quality=95)
    return np.asarray(Image.open(buffer).convert("RGB"))


def test_in_memory_frames_equal_the_written_and_read_ones(tmp_path: Path) -> None:
    memory = SyntheticSequence(CONFIG)
    disk = ReplicaSequence(write_synthetic_sequence(tmp_path / "seq", CONFIG))
    assert isinstance(memory, RGBDSequence)
    assert len(memory) == len(disk) == CONFIG.frames
    assert memory.intrinsics == disk.intrinsics
    np.testing.assert_array_equal(memory.timestamps(), disk.timestamps())
    np.testing.assert_allclose(memory.gt_poses(), disk.gt_poses(), rtol=0, atol=1e-6)
    for index in range(len(memory)):
        ours, read = memory[index], disk[index]
        assert ours.index == read.index and ours.timestamp == read.timestamp
        assert ours.intrinsics == read.intrinsics
        np.testing.assert_allclose(ours.pose_gt, read.pose_gt, rtol=0, atol=1e-6)
        # depth: the PNG stores round(d * 6553.5); 0 (missing) stays 0
        assert np.abs(ours.depth - read.depth).max() <= 0.5 / REPLICA_DEPTH_SCALE + 1e-6
        np.testing.assert_array_equal(ours.depth == 0, read.depth == 0)
        # colour: the writer stores JPEG, so the file holds exactly our colour's JPEG
        np.testing.assert_array_equal(_jpeg(ours.rgb), read.rgb)


def test_frames_are_generate_sequences_with_frame_number_timestamps() -> None:
    memory = SyntheticSequence(CONFIG)
    for frame in generate_sequence(CONFIG):
        ours = memory[frame.index]
        np.testing.assert_array_equal(ours.rgb, frame.rgb)
        np.testing.assert_array_equal(ours.depth, frame.depth)
        np.testing.assert_array_equal(ours.pose_gt, frame.pose_gt)
        assert ours.timestamp == frame.index  # generate_sequence stamps index / FPS seconds


def test_a_short_sequence_is_a_prefix_and_indexing_is_checked() -> None:
    short = SyntheticSequence(SynthConfig(frames=2, width=80, height=60, seed=3))
    long = SyntheticSequence(SynthConfig(frames=5, width=80, height=60, seed=3))
    np.testing.assert_array_equal(short.gt_poses(), long.gt_poses()[:2])
    np.testing.assert_array_equal(short[1].rgb, long[1].rgb)
    with pytest.raises(IndexError, match="frame 2 out of range for 2 frames"):
        short[2]
    poses = short.gt_poses()
    poses[:] = 0.0  # a copy: the sequence is unchanged
    assert short.gt_poses()[0, 3, 3] == 1.0
    assert short.root == Path("synthetic-room-seed3")
    assert SyntheticSequence(CONFIG, root="memory").root == Path("memory")
