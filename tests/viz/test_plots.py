"""Trajectory plots: files written, principal axes as expected."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from eslam.viz.plots import plot_trajectories, plot_translation_error, principal_axes


def _circle(n: int = 50) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n)
    # a 2 m circle in the x-z plane with 5 cm of height wobble along y
    return np.stack([np.cos(t), 0.05 * np.sin(3 * t), np.sin(t)], axis=1)


def test_principal_axes_find_the_floor_plane() -> None:
    axes = principal_axes(_circle())
    assert abs(axes[2] @ np.array([0.0, 1.0, 0.0])) > 0.99  # smallest spread: the up axis


def test_plots_are_written(tmp_path: Path) -> None:
    gt = _circle()
    estimated = gt + np.random.default_rng(0).normal(0, 0.01, gt.shape)
    plot_trajectories(gt, estimated, tmp_path / "trajectory.png")
    errors = np.linalg.norm(estimated - gt, axis=1)
    plot_translation_error(np.arange(len(gt)), errors, tmp_path / "error.png")
    for name in ("trajectory.png", "error.png"):
        with Image.open(tmp_path / name) as image:
            assert image.format == "PNG"
            pixels = np.asarray(image.convert("RGB"))
        assert pixels.shape[1] > 800
        red = (pixels[..., 0] > 150) & (pixels[..., 1] < 100) & (pixels[..., 2] < 100)
        assert red.sum() > 100, f"{name}: the estimated curve (red) is drawn"
    assert not list(tmp_path.glob("*.tmp*")), "atomic writes leave no temporary files"
