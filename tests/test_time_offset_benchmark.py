"""benchmarks/time_offset.py: the ATE against ground truth read at t + offset finds a
known clock offset between an estimate and its ground truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "time_offset.py"


def _path(t: np.ndarray) -> np.ndarray:
    """A moving, turning camera: (len(t), 4, 4)."""
    poses = np.tile(np.eye(4), (len(t), 1, 1))
    yaw = 0.8 * np.sin(1.3 * t)
    poses[:, 0, 0], poses[:, 0, 1] = np.cos(yaw), -np.sin(yaw)
    poses[:, 1, 0], poses[:, 1, 1] = np.sin(yaw), np.cos(yaw)
    poses[:, :3, 3] = np.stack([np.sin(t), np.cos(0.7 * t), 0.3 * t], axis=1)
    return poses


def test_a_known_offset_is_found() -> None:
    script = load_script(SCRIPT)
    truth_times = np.arange(0.0, 20.0, 0.01)  # motion capture at 100 Hz
    frames = np.arange(1.0, 19.0, 1 / 30)
    estimate = _path(frames + 0.02)  # the camera's clock 20 ms behind
    offsets = np.round(np.arange(-0.04, 0.0401, 0.01), 6)
    rows = script.offset_errors(frames, estimate, truth_times, _path(truth_times), offsets)
    errors = {round(offset, 3): error for offset, error, _ in rows}
    assert errors[0.02] < 0.01 < errors[0.0]
    assert min(errors, key=errors.get) == 0.02


def test_a_clock_that_slips_shows_in_its_windows_only() -> None:
    script = load_script(SCRIPT)
    truth_times = np.arange(0.0, 20.0, 0.01)
    frames = np.arange(1.0, 19.0, 1 / 30)
    late = frames < 10.0  # the first half's frames stamped 30 ms after they were taken
    estimate = _path(np.where(late, frames - 0.03, frames))
    rows = script.window_lags(frames, estimate, truth_times, _path(truth_times), 90)
    lags = np.array([lag for _, _, lag, _ in rows])
    firsts = np.array([first for first, _, _, _ in rows])
    first_half = firsts + 90 <= int(late.sum())
    second_half = firsts >= int(late.sum())
    assert np.all(np.abs(lags[first_half] - 0.03) < 0.006)
    assert np.all(np.abs(lags[second_half]) < 0.006)
    assert sum(count for _, count, _, _ in rows) == len(frames)
