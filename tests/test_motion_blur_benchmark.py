"""benchmarks/motion_blur.py: sharpness against turn rate and error, keyframes split by blur."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eslam.io.trajectory import write_tum_trajectory
from eslam.synthetic import SynthConfig, SyntheticSequence
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "motion_blur.py"


def _turning(count: int, degrees_per_frame: np.ndarray) -> np.ndarray:
    """A camera turning about z by the given angle into each frame (index 1 on)."""
    poses = np.tile(np.eye(4), (count, 1, 1))
    angles = np.radians(np.concatenate([[0.0], np.cumsum(degrees_per_frame)]))
    poses[:, :3, :3] = Rotation.from_rotvec(np.outer(angles, [0, 0, 1])).as_matrix()
    poses[:, 0, 3] = 0.01 * np.arange(count)
    return poses


def test_sharpness_falls_with_blur() -> None:
    script = load_script(SCRIPT)
    rgb = SyntheticSequence(SynthConfig(frames=1, width=160, height=120, seed=0))[0].rgb
    sharp = script.image_sharpness(rgb)
    once = script.image_sharpness(cv2.GaussianBlur(rgb, (0, 0), 1.0))
    assert sharp > 0 and once < 0.6 * sharp
    assert script.image_sharpness(cv2.GaussianBlur(rgb, (0, 0), 3.0)) < once
    assert script.image_sharpness(np.full_like(rgb, 128)) == 0.0
    with pytest.raises(ValueError, match="colour image"):
        script.image_sharpness(rgb[..., 0])


def test_blur_is_judged_against_the_recent_median() -> None:
    script = load_script(SCRIPT)
    history = [1.0, 1.2, 0.8]
    assert script.is_blurred(0.6, history, 0.7) and not script.is_blurred(0.8, history, 0.7)
    assert not script.is_blurred(0.0, history[:2], 0.7)  # too little known
    assert script.is_blurred(0.6, [*history, 100.0, 0.1], 0.7)  # the median, not the mean


def test_turn_rates_are_degrees_per_second() -> None:
    script = load_script(SCRIPT)
    truth = _turning(4, np.array([1.0, 2.0, 0.5]))
    times = np.array([0.0, 0.1, 0.2, 0.4])
    assert script.turn_rates(truth, times) == pytest.approx([10.0, 20.0, 2.5], rel=1e-6)


def test_blurred_keyframes_carry_the_steps_put_after_them() -> None:
    script = load_script(SCRIPT)
    count = 40
    blurred = {10, 20}  # keyframes every 5th frame, two of them blurred; frame 0 has no step
    sharpness = np.ones(count)
    sharpness[list(blurred)] = 0.2
    turn = np.full(count - 1, 0.5)
    turn[[k - 1 for k in blurred]] = 3.0  # the blurred frames turned fast into them
    truth = _turning(count, turn)
    estimate = truth.copy()
    for k in blurred:  # the step after a blurred keyframe errs by 4 mm
        estimate[k + 1 :, 1, 3] += 0.004
    times = np.arange(count) / 30.0
    lines = script.report(sharpness, truth, estimate, times, list(range(0, count, 5)), 0.7)
    rank = re.search(r"turn rate ([+-][0-9.]+)", lines[0])
    assert rank is not None and float(rank.group(1)) < -0.3  # the fast turns are blurred
    blurred_row = next(line for line in lines if line.startswith("| blurred |"))
    sharp_row = next(line for line in lines if line.startswith("| sharp |"))
    assert blurred_row.split("|")[2].strip() == "2"
    assert blurred_row.split("|")[4].strip() == "4.00 mm"
    assert sharp_row.split("|")[2].strip() == "5" and sharp_row.split("|")[4].strip() == "0.00 mm"
    thirds = [line for line in lines if "third |" in line]
    assert [int(line.split("|")[2]) for line in thirds] == [13, 13, 13]


def test_a_folder_without_a_run_is_one_line_and_status_2(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    assert script.main([str(tmp_path)]) == 2
    assert "trajectory.txt: missing" in capsys.readouterr().err


def test_a_run_of_another_version_is_one_line_and_status_2(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    for name in ("trajectory.txt", "trajectory_gt.txt"):
        write_tum_trajectory(tmp_path / name, np.arange(2.0), np.tile(np.eye(4), (2, 1, 1)))
    (tmp_path / "map.pt").write_text("")
    (tmp_path / "config.yaml").write_text("mapping:\n  no_such_setting: 1\n")
    assert script.main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'mapping.no_such_setting'" in err and len(err.strip().splitlines()) == 1
