"""Trajectory plots for report.md: top and side views, per-frame translation error.

matplotlib (the ``[viz]`` extra) is imported when a plot is drawn, with the Agg
backend, so plots work headless. Images are written atomically as PNG.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eslam.atomic import write_with
from eslam.errors import ESLAMError


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise ESLAMError(
            'plots need matplotlib: pip install "eslam[viz]" (or pip install matplotlib)'
        ) from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def principal_axes(points: np.ndarray) -> np.ndarray:
    """(3, 3) rows = the principal directions of ``points`` (N, 3), largest spread first.

    A top view of a hand-held trajectory is its two largest directions (the floor
    plane, whatever the dataset's up axis); a side view is the largest and the smallest.
    """
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return vt


def plot_trajectories(gt: np.ndarray, estimated: np.ndarray, path: str | Path) -> None:
    """Top and side views of the ground-truth and (aligned) estimated camera positions.

    Args:
        gt: (N, 3) ground-truth positions, metres.
        estimated: (N, 3) estimated positions after alignment to ``gt``, metres.
        path: PNG file to write.
    """
    plt = _pyplot()
    axes_3d = principal_axes(gt) if len(gt) >= 3 else np.eye(3)
    origin = gt.mean(axis=0)
    g = (gt - origin) @ axes_3d.T
    e = (estimated - origin) @ axes_3d.T
    figure, (top, side) = plt.subplots(1, 2, figsize=(10, 4.5))
    for ax, (i, j), title in ((top, (0, 1), "top view"), (side, (0, 2), "side view")):
        ax.plot(g[:, i], g[:, j], "-", color="black", lw=1.5, label="ground truth")
        ax.plot(e[:, i], e[:, j], "-", color="tab:red", lw=1.0, label="estimated")
        ax.plot(g[0, i], g[0, j], "o", color="black", ms=4)
        ax.set_title(title)
        ax.set_xlabel(f"principal axis {i + 1} (m)")
        ax.set_ylabel(f"principal axis {j + 1} (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    top.legend(loc="best")
    figure.tight_layout()
    write_with(path, lambda tmp: figure.savefig(tmp, format="png", dpi=110))
    plt.close(figure)


def plot_translation_error(timestamps: np.ndarray, errors_m: np.ndarray, path: str | Path) -> None:
    """Per-frame translation error (cm) of the aligned trajectory against time or frame.

    Args:
        timestamps: (N,) frame times (seconds) or frame numbers.
        errors_m: (N,) distance between aligned estimated and ground-truth positions, m.
        path: PNG file to write.
    """
    plt = _pyplot()
    figure, ax = plt.subplots(figsize=(10, 3.2))
    ax.plot(timestamps, 100 * errors_m, "-", color="tab:red", lw=1.0)
    ax.axhline(100 * float(np.sqrt(np.mean(errors_m**2))), color="gray", ls="--", lw=1.0,
               label="RMSE")  # fmt: skip
    ax.set_xlabel("timestamp")
    ax.set_ylabel("translation error (cm)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    figure.tight_layout()
    write_with(path, lambda tmp: figure.savefig(tmp, format="png", dpi=110))
    plt.close(figure)
