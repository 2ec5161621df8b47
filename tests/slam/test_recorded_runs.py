"""Runs on recordings: any config (the demo's) runs on a ROS bag named by --data, its
format detected, and writes the usual run folder."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from eslam.cli import main
from eslam.config import DataConfig, load_config
from eslam.data import open_sequence
from eslam.slam.session import run_slam
from eslam.synthetic import read_synthetic_bound
from eslam.testing.recordings import BagLayout, write_ros_bag
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY

FRAMES = 3
"""Frames of the tiny sequence recorded (a few: the runs are end-to-end checks)."""

QUICK = (
    *TINY,
    "mapping.first_iterations=8",
    "mapping.iterations=3",
    "tracking.render.iterations=4",
)
"""The tiny settings, shorter still: these tests check the plumbing, not the accuracy."""

RUN_FILES = ("config.yaml", "trajectory.txt", "map.pt", "mesh.ply", "metrics.json")


@pytest.fixture(scope="module")
def frames(tiny_sequence: Path) -> list:
    sequence = open_sequence(DataConfig(path=str(tiny_sequence)))
    return [sequence[i] for i in range(FRAMES)]


@pytest.mark.slow
def test_a_ros2_bag_runs_end_to_end_with_its_pose_topic_as_ground_truth(
    tiny_sequence: Path, frames: list, tmp_path: Path
) -> None:
    bag = write_ros_bag(tmp_path / "rec", frames, BagLayout("mcap", pose_topic="/gt"))
    bound = read_synthetic_bound(tiny_sequence)
    overrides = [f"data.path={bag}", f"scene.bound={bound}", "data.topics.pose=/gt", *QUICK]
    result = run_slam(load_config(DEMO_CONFIG, overrides), tmp_path / "run")
    for name in (*RUN_FILES, "trajectory_gt.txt"):
        assert (result.run_dir / name).is_file(), name
    saved = yaml.safe_load((result.run_dir / "config.yaml").read_text())
    assert saved["data"]["format"] == "rosbag"  # detected, and recorded for resume
    assert result.poses.shape == (FRAMES, 4, 4)
    assert result.metrics["ate_rmse_cm"] < 10.0  # finite, from the pose topic


@pytest.mark.slow
def test_eslam_run_and_inspect_take_a_ros1_bag(
    tiny_sequence: Path, frames: list, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_ros_bag(tmp_path / "rec.bag", frames, BagLayout("ros1", "bgr8"))
    assert main(["inspect", str(bag)]) == 0
    assert f"{FRAMES}" in capsys.readouterr().out
    out = tmp_path / "run"
    bound = read_synthetic_bound(tiny_sequence)
    command = ["run", str(DEMO_CONFIG), "--data", str(bag), "--out", str(out)]
    assert main([*command, f"scene.bound={bound}", *QUICK]) == 0
    for name in RUN_FILES:
        assert (out / name).is_file(), name
    trajectory = [line for line in (out / "trajectory.txt").read_text().splitlines()]
    assert len([line for line in trajectory if not line.startswith("#")]) == FRAMES
