"""A run read back from its folder: config, trajectories, metrics and where the map is.

``load_run(run_dir)`` is the Python side of a run folder (see :mod:`eslam.io.run_dir`
for the files): what ``eslam run`` wrote, for notebooks, scripts and other tools.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.config import ESLAMConfig, load_config
from eslam.errors import InputError
from eslam.io.run_dir import RunDirectory, read_json
from eslam.io.trajectory import read_tum_trajectory


@dataclass(frozen=True, eq=False)
class SavedRun:
    """What a run folder holds.

    Attributes:
        root: the run folder.
        config: the run's fully resolved configuration (config.yaml).
        timestamps: (N,) float64 seconds or frame numbers of the estimated poses.
        poses: (N, 4, 4) float64 estimated camera-to-world poses (trajectory.txt);
            an all-NaN matrix is a missing pose.
        gt_timestamps: (M,) float64 timestamps of the ground truth, or None.
        gt_poses: (M, 4, 4) float64 ground-truth poses (trajectory_gt.txt), or None
            when the sequence had no ground truth.
        metrics: metrics.json's keys and values (empty when the file is absent).
        map_path: map.pt (the checkpoint to resume or re-mesh from), or None.
        mesh_path: mesh.ply, or None.
    """

    root: Path
    config: ESLAMConfig
    timestamps: np.ndarray
    poses: np.ndarray
    gt_timestamps: np.ndarray | None
    gt_poses: np.ndarray | None
    metrics: dict[str, object]
    map_path: Path | None
    mesh_path: Path | None


def _existing(path: Path) -> Path | None:
    return path if path.is_file() else None


def load_run(run_dir: str | Path) -> SavedRun:
    """Read the run in ``run_dir``: config.yaml, trajectory.txt, and what else is there.

    Raises:
        InputError: ``run_dir`` is not a run folder (no config.yaml), the run has not
            written its trajectory yet, or a file is unreadable (each names the file and
            the fix).
        ConfigError: config.yaml is not a valid eslam config.
    """
    run = RunDirectory(Path(run_dir))
    if not run.root.is_dir():
        problem = "is a file, not a run folder" if run.root.exists() else "not found"
        raise InputError(run.root, problem, "pass a run folder written by `eslam run`")
    if not run.config.is_file():
        raise InputError(
            run.config, "not found: not a run folder", "pass a folder written by `eslam run`"
        )
    if not run.trajectory.is_file():
        raise InputError(
            run.trajectory,
            "not found: the run saved no frame yet",
            f"continue it with `eslam resume {run.root}`",
        )
    timestamps, poses = read_tum_trajectory(run.trajectory, allow_missing=True)
    gt_timestamps = gt_poses = None
    if run.trajectory_gt.is_file():
        gt_timestamps, gt_poses = read_tum_trajectory(run.trajectory_gt, allow_missing=True)
    metrics: object = read_json(run.metrics) if run.metrics.is_file() else {}
    if not isinstance(metrics, dict):
        raise InputError(run.metrics, "is not a JSON object", "rewrite it with `eslam eval`")
    return SavedRun(
        root=run.root,
        config=load_config(run.config),
        timestamps=timestamps,
        poses=poses,
        gt_timestamps=gt_timestamps,
        gt_poses=gt_poses,
        metrics=metrics,
        map_path=_existing(run.map),
        mesh_path=_existing(run.mesh),
    )
