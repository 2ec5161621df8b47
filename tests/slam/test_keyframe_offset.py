"""Frames after a keyframe follow the mapper's pose of it (tracking.keyframe_offset)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.geometry.pose import se3_exp
from eslam.io.trajectory import read_tum_trajectory
from eslam.slam.session import run_slam
from eslam.slam.tracking.base import TrackingResult
from eslam.slam.tracking.keyframe_offset import keyframe_offset
from eslam.slam.tracking.trackers import TRACKERS
from tests.conftest import tiny_config


def test_the_offset_takes_the_trackers_pose_to_the_mappers() -> None:
    generator = torch.Generator().manual_seed(0)
    mapped = se3_exp(0.3 * torch.randn(5, 6, generator=generator, dtype=torch.float64))
    tracked = se3_exp(0.01 * torch.randn(5, 6, generator=generator, dtype=torch.float64)) @ mapped
    offset = keyframe_offset(mapped, tracked)
    torch.testing.assert_close(offset @ tracked, mapped, rtol=0, atol=1e-12)
    torch.testing.assert_close(
        keyframe_offset(mapped, mapped), torch.eye(4, dtype=torch.float64).expand(5, 4, 4)
    )


BIAS = np.array([0.01, 0.0, 0.0])
"""Where the biased tracker's optimum lies from the rendering tracker's: 1 cm along
world x."""


class Biased:
    """The rendering tracker whose every answer lies :data:`BIAS` off: a tracker whose
    optimum differs from the mapper's (as the SDF tracker's does on real data)."""

    def __init__(self, config) -> None:
        self.real = TRACKERS.make("render", config)

    def track(self, field, view, initial_pose, generator):
        result = self.real.track(field, view, initial_pose, generator)
        pose = result.pose.clone()
        pose[:3, 3] += torch.as_tensor(BIAS).to(pose)
        return TrackingResult(pose, result.loss, result.quality)


def _biased_config(sequence: Path, offset: bool):
    config = tiny_config(
        sequence, "output.mesh=false", "mapping.every=3", f"tracking.keyframe_offset={offset}"
    )
    return dataclasses.replace(
        config, tracking=dataclasses.replace(config.tracking, method="biased")
    )


@pytest.mark.slow
def test_frames_follow_the_mapper_not_a_biased_tracker(
    tiny_sequence: Path, tmp_path: Path, register
) -> None:
    register(TRACKERS, "biased", Biased)
    off = run_slam(_biased_config(tiny_sequence, False), tmp_path / "off")
    on = run_slam(_biased_config(tiny_sequence, True), tmp_path / "on")
    assert "tracking_keyframe_offsets" not in off.metrics
    # each call's keyframe, tracked again, lies about the bias from the mapper's pose ...
    assert on.metrics["tracking_keyframe_offsets"] >= 2
    assert 7.0 < on.metrics["tracking_keyframe_offset_mm"] < 16.0
    # ... and the frames tracked after it are moved back by it: the bias leaves the
    # trajectory (the mapper holds the keyframes near the truth either way)
    gt = read_tum_trajectory(tmp_path / "on" / "trajectory_gt.txt")[1][:, :3, 3]
    error_off = np.linalg.norm(off.poses[:, :3, 3] - gt, axis=1)
    error_on = np.linalg.norm(on.poses[:, :3, 3] - gt, axis=1)
    assert error_off.mean() > 0.006
    assert error_on.mean() < 0.2 * error_off.mean()


@pytest.mark.slow
def test_a_resumed_run_keeps_the_offset(tiny_sequence: Path, tmp_path: Path, register) -> None:
    register(TRACKERS, "biased", Biased)
    config = _biased_config(tiny_sequence, True)
    whole = run_slam(config, tmp_path / "whole")
    run_slam(config, tmp_path / "stopped", stop_after=5)  # after frame 3's call
    resumed = run_slam(config, tmp_path / "stopped", resume=True)
    np.testing.assert_array_equal(resumed.poses, whole.poses)
    assert (
        resumed.metrics["tracking_keyframe_offsets"] == whole.metrics["tracking_keyframe_offsets"]
    )
