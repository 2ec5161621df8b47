"""benchmarks/colour_timing.py: colour moved by the camera's motion over the colour-depth
time gap lines up with the depth only when the two images were taken apart."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.config import load_config
from eslam.data.tum import TUM_CAMERAS
from eslam.geometry import interpolate_pose
from eslam.synthetic import FPS, SynthConfig, build_scene, camera_trajectory, render_frame
from eslam.testing.scripts import load_script
from eslam.testing.tum import DEPTH_DELAY, write_tum_sequence
from eslam.types import Frame

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "colour_timing.py"
FRAMES = 4


def _sequence(root: Path, apart: bool) -> Path:
    """A fast synthetic camera (3 cm and 2 degrees a frame) written in TUM's layout;
    with ``apart`` each depth image is rendered where the camera is DEPTH_DELAY after
    its colour image (as the Kinect takes them), else both at the colour's pose."""
    config = SynthConfig(frames=FRAMES + 1, seed=2, step_translation=0.03, step_rotation_deg=2.0)
    scene = build_scene(config.scene, config.seed)
    poses = camera_trajectory(scene, config)
    k = TUM_CAMERAS["fr3"].intrinsics
    share = DEPTH_DELAY * FPS
    frames = []
    for i in range(FRAMES):
        rgb, depth = render_frame(scene, k, poses[i])
        if apart:
            later = interpolate_pose(
                torch.from_numpy(poses[i]), torch.from_numpy(poses[i + 1]), share
            ).numpy()
            depth = render_frame(scene, k, later)[1]
        frames.append(Frame(i, rgb, depth, k, poses[i], i / FPS))
    folder = root / "rgbd_dataset_freiburg3_synthetic"
    write_tum_sequence(folder, frames, camera="fr3")
    return folder


@pytest.mark.parametrize("apart", [True, False])
def test_moving_the_colour_helps_only_where_the_images_were_taken_apart(
    tmp_path: Path, apart: bool
) -> None:
    script = load_script(SCRIPT)
    data = _sequence(tmp_path, apart)
    shifts = [(0.0, 0.0), (1.0, 0.0)]
    config = load_config("tum/tum_cpu")
    scores = script.measure(config, data, 1, 0.025, shifts)
    assert len(scores) == FRAMES
    for score in scores:
        assert score.gap_ms == pytest.approx(-1e3 * DEPTH_DELAY, abs=1e-3)
    # the last frame has no later ground-truth sample: its depth-time pose is its
    # colour-time one, so nothing moves there
    moved = np.array([score.moved for score in scores[:-1]])
    as_read = np.array([score.shifted[0] for score in scores[:-1]])
    assert scores[-1].moved == pytest.approx(scores[-1].shifted[0])
    if apart:
        assert (moved > as_read).all()
    else:
        assert (moved < as_read).all()


def test_a_sequence_without_ground_truth_is_one_line(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    data = _sequence(tmp_path, False)
    (data / "groundtruth.txt").unlink()
    with pytest.raises(SystemExit) as stop:
        script.main(["--data", str(data)])
    assert stop.value.code == 2
    assert "groundtruth.txt" in capsys.readouterr().err
