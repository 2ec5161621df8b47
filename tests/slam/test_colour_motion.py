"""A keyframe's colour moved to its depth image's time (``mapping.colour_motion``), with
exact renderings: the colour taken where the camera was ``delay`` seconds off its depth
image, moved by the camera's last step, matches the colour at the depth's pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.config import DataConfig
from eslam.data.tum import TUM_CAMERAS, TUMSequence
from eslam.geometry.pose import invert, se3_exp, se3_log
from eslam.slam.mapping.colour_motion import (
    colour_at_depth_time,
    colour_from_depth,
    moves_colour,
)
from eslam.slam.trajectory import Trajectory
from eslam.synthetic import FPS, SynthConfig, build_scene, camera_trajectory, render_frame
from eslam.testing.tum import DEPTH_DELAY, write_tum_sequence
from eslam.types import Frame, Intrinsics

ROOM = SynthConfig(
    frames=3, width=160, height=120, seed=0, step_translation=0.03, step_rotation_deg=2.0
)
"""The synthetic room, 3 cm and 2 degrees a frame (fast for a hand-held camera)."""
DELAY = -0.015
"""The colour image taken 15 ms before the depth image."""


def _rooms() -> tuple[object, np.ndarray, Intrinsics]:
    scene = build_scene(ROOM.scene, ROOM.seed)
    poses = camera_trajectory(scene, ROOM)
    k = Intrinsics(ROOM.width, ROOM.height, 120.0, 120.0, 79.5, 59.5)
    return scene, poses, k


def test_the_colour_at_the_depth_time_is_found() -> None:
    scene, poses, k = _rooms()
    previous, current = torch.from_numpy(poses[0]), torch.from_numpy(poses[1])
    # where the camera was when the colour was taken: the last step's velocity
    share = DELAY * FPS
    colour_pose = current @ se3_exp(share * se3_log(invert(previous) @ current))
    rgb_then = render_frame(scene, k, colour_pose.numpy())[0]
    rgb_now, depth = render_frame(scene, k, poses[1])
    trajectory = Trajectory()
    for i in range(2):
        trajectory.append(torch.from_numpy(poses[i]).float(), i / FPS, None)
    frame = Frame(1, rgb_then, depth, k, poses[1], 1 / FPS, colour_delay=DELAY)
    moved = colour_at_depth_time(frame, trajectory, 1)
    valid = depth > 0
    before = np.abs(rgb_then.astype(float) - rgb_now)[valid].mean()
    after = np.abs(moved.rgb.astype(float) - rgb_now)[valid].mean()
    assert after < 0.5 * before
    np.testing.assert_array_equal(moved.depth, frame.depth)


def test_nothing_moves_without_a_delay_or_a_motion() -> None:
    scene, poses, k = _rooms()
    rgb, depth = render_frame(scene, k, poses[1])
    trajectory = Trajectory()
    for i in range(2):
        trajectory.append(torch.from_numpy(poses[i]).float(), i / FPS, None)
    together = Frame(1, rgb, depth, k, poses[1], 1 / FPS)
    assert colour_at_depth_time(together, trajectory, 1) is together
    still = torch.from_numpy(poses[1])
    np.testing.assert_allclose(colour_from_depth(still, still, 1 / FPS, DELAY), np.eye(4))
    np.testing.assert_allclose(colour_from_depth(still, still, 0.0, DELAY), np.eye(4))


def test_the_tum_reader_gives_each_frame_its_colour_delay(tmp_path: Path) -> None:
    scene, poses, _ = _rooms()
    k = TUM_CAMERAS["fr3"].intrinsics
    frames = [
        Frame(i, *render_frame(scene, k, pose), k, pose, i / FPS) for i, pose in enumerate(poses)
    ]
    root = tmp_path / "rgbd_dataset_freiburg3_synthetic"
    write_tum_sequence(root, frames, camera="fr3")
    for stamp in ("colour", "depth"):
        sequence = TUMSequence(root, DataConfig(format="tum", stamp=stamp))
        assert sequence[1].colour_delay == pytest.approx(-DEPTH_DELAY, abs=1e-6)


@pytest.mark.parametrize(
    ("setting", "real_time", "moves"),
    [(True, False, True), (True, True, False), (False, False, False), (False, True, False)],
)
def test_the_colour_moves_on_recorded_data_only(
    setting: bool, real_time: bool, moves: bool
) -> None:
    """In real time the last step spans dropped frames: the colour is kept as read."""
    assert moves_colour(setting, real_time) is moves
