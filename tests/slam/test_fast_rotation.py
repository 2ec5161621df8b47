"""Fast rotation with exact ground truth: the synthetic room turning at 4 degrees a
frame (120 degrees per second at 30 fps) is tracked by the demo's CPU preset without a
failed frame, to a fraction of the error of a camera held still (its position and its
rotation from frame to frame)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.evaluate.trajectory import absolute_trajectory_error, relative_pose_error
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig, write_synthetic_sequence
from tests.conftest import demo_config


@pytest.mark.slow
def test_a_fast_yaw_is_tracked_without_a_failed_frame(tmp_path: Path) -> None:
    room = SynthConfig(frames=16, width=120, height=90, seed=0, step_rotation_deg=4.0)
    data = write_synthetic_sequence(tmp_path / "room", room)
    config = demo_config(data)
    result = run_slam(config, tmp_path / "run")
    metrics = result.metrics
    assert metrics["tracking_failures"] == 0
    assert metrics["tracking_recovered_frames"] == {"start": 0, "relocalised": 0}
    truth = np.loadtxt(data / "traj.txt").reshape(-1, 4, 4)
    held = np.repeat(truth[:1], len(truth), axis=0)  # a tracker that never moves
    still_cm = absolute_trajectory_error(held, truth).as_cm()["ate_rmse_cm"]
    still_deg = relative_pose_error(held, truth).as_dict()["rpe_rotation_rmse_deg"]
    assert metrics["ate_rmse_cm"] < 1.0 < still_cm / 4
    assert metrics["rpe_rotation_rmse_deg"] < 0.5 < still_deg / 4
