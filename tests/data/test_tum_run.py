"""A short SLAM run on a TUM folder without groundtruth.txt (identity first pose)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.data.tum import TUM_CAMERAS
from eslam.geometry.pose import pose_distance
from eslam.io.trajectory import read_tum_trajectory
from eslam.slam.session import run_slam
from eslam.slam.state import load_state
from eslam.synthetic import (
    FPS,
    SynthConfig,
    build_scene,
    camera_trajectory,
    render_frame,
    scene_bound,
)
from eslam.testing import write_tum_sequence
from eslam.testing.tum import DEPTH_DELAY
from eslam.types import Frame
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY as LOOP_TINY

FRAMES = 6
# tests/slam/test_loop.py's tiny settings; 30 tracking steps follow the true motion
# (with 8 the estimate lags it by about half)
TINY = [*LOOP_TINY, "tracking.render.iterations=30"]


def _bound_in_first_camera(corners_bound: list[list[float]], first: np.ndarray) -> list:
    """Axis-aligned box, in the first camera's frame, around a world box."""
    lo, hi = np.array(corners_bound).T
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    local = (corners - first[:3, 3]) @ first[:3, :3]  # R^T (p - t), row-wise
    return [[float(a), float(b)] for a, b in zip(local.min(0), local.max(0), strict=True)]


def test_run_on_a_folder_without_groundtruth(tmp_path: Path) -> None:
    config = SynthConfig(frames=FRAMES, seed=3)
    scene = build_scene(config.scene, config.seed)
    poses = camera_trajectory(scene, config)
    k = TUM_CAMERAS["fr3"].intrinsics
    frames = [Frame(i, *render_frame(scene, k, p), k, p, i / FPS) for i, p in enumerate(poses)]
    data = tmp_path / "rgbd_dataset_freiburg3_synthetic"
    write_tum_sequence(data, frames, camera="fr3", with_groundtruth=False)
    bound = _bound_in_first_camera(scene_bound(scene), poses[0])
    overrides = [
        f"data.path={data}",
        "data.format=tum",
        "data.resize=[80, 60]",
        "data.crop=2",
        f"scene.bound={bound}",
        *TINY,
    ]
    result = run_slam(load_config(DEMO_CONFIG, overrides), tmp_path / "run")
    root = result.run_dir
    assert not (root / "trajectory_gt.txt").exists()
    metrics = json.loads((root / "metrics.json").read_text())
    assert metrics["frames"] == FRAMES and "ate_rmse_cm" not in metrics
    written = read_tum_trajectory(root / "trajectory.txt")[1]
    assert len(written) == FRAMES
    np.testing.assert_allclose(written[0], np.eye(4), atol=1e-6)
    # the estimate follows the true motion relative to the first frame
    truth = torch.from_numpy(np.linalg.inv(poses[0]) @ poses)
    translation, rotation = pose_distance(torch.from_numpy(written), truth)
    # measured: at most 7.4 mm and 0.45 deg, while the camera moves 3.6 cm in all
    assert float(truth[-1, :3, 3].norm()) > 0.03
    assert float(translation.max()) < 0.015 and float(rotation.max()) < np.radians(1.0)


@pytest.mark.parametrize("moved", [True, False])
def test_keyframe_colour_moves_to_the_depth_time_only_when_asked(
    tmp_path: Path, moved: bool
) -> None:
    """``mapping.colour_motion``: a keyframe after the first stores its colour moved by
    the camera's last step over TUM's colour-depth gap (the writer's depth comes 10 ms
    after the colour); without it, the colour as read."""
    config = SynthConfig(frames=4, seed=3)
    scene = build_scene(config.scene, config.seed)
    poses = camera_trajectory(scene, config)
    k = TUM_CAMERAS["fr3"].intrinsics
    frames = [Frame(i, *render_frame(scene, k, p), k, p, i / FPS) for i, p in enumerate(poses)]
    data = tmp_path / "rgbd_dataset_freiburg3_synthetic"
    write_tum_sequence(data, frames, camera="fr3")
    overrides = [
        f"data.path={data}",
        "data.format=tum",
        "data.resize=[80, 60]",
        "data.crop=2",
        f"scene.bound={_bound_in_first_camera(scene_bound(scene), poses[0])}",
        "mapping.every=2",
        f"mapping.colour_motion={str(moved).lower()}",
        *TINY,
    ]
    run_config = load_config(DEMO_CONFIG, overrides)
    run_slam(run_config, tmp_path / "run")
    state = load_state(tmp_path / "run" / "map.pt", run_config, torch.device("cpu"))
    sequence = open_sequence(run_config.data)
    store = state.keyframes
    later = [k for k, f in enumerate(store.frame_indices) if f > 0]
    assert later
    for keyframe in later:
        read = sequence[store.frame_indices[keyframe]]
        stored = np.rint(store.rgb(keyframe).numpy() * 255).astype(np.uint8)
        assert read.colour_delay == pytest.approx(-DEPTH_DELAY, abs=1e-6)
        assert np.array_equal(stored, read.rgb) is not moved
