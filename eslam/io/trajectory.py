"""Trajectory files: TUM (read and write), Replica ``traj.txt`` and run folders (read).

TUM format (the one ``trajectory.txt`` of a run folder uses): one pose per line,
``timestamp tx ty tz qx qy qz qw``, camera-to-world, translation in metres, quaternion
scalar-last; lines starting with ``#`` are comments. Our poses are camera-to-world in
OpenCV camera axes, and so are the TUM ground-truth files (the optical frame), so no
axis conversion happens here. Lines are parsed by :mod:`eslam.io.pose_files`, the one
pose-file parser.

Numbers are written with Python's shortest round-trip representation, so reading a
file back gives the very float64 values written: poses survive a round trip to
rounding of the quaternion conversion (about 1e-15).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from eslam.atomic import write_text
from eslam.errors import InputError
from eslam.geometry.rotation import matrix_to_quaternion, orthonormalize_rotation
from eslam.io.pose_files import (
    MATRIX_COLUMNS,
    TUM_COLUMNS,
    matrix_poses,
    read_pose_table,
    tum_poses,
)

TUM_HEADER = "# timestamp tx ty tz qx qy qz qw (camera-to-world, OpenCV camera axes, metres)"
"""First line of every TUM file we write (readers skip ``#`` comments)."""
RUN_TRAJECTORY = "trajectory.txt"
"""Estimated trajectory of a run folder (see :mod:`eslam.io.run_dir`)."""
RUN_TRAJECTORY_GT = "trajectory_gt.txt"
"""Ground-truth trajectory of a run folder (see :mod:`eslam.io.run_dir`)."""


def _as_float64(values: object) -> np.ndarray:
    if isinstance(values, torch.Tensor):
        values = values.detach().cpu().numpy()
    return np.asarray(values, dtype=np.float64)


def _number(value: float) -> str:
    return repr(float(value))


def write_tum_trajectory(path: str | Path, timestamps: object, poses: object) -> None:
    """Write camera-to-world poses as a TUM trajectory, atomically.

    Each rotation is projected onto the nearest rotation (SVD) before it becomes a
    quaternion (w >= 0), so slightly non-orthonormal input (float32 estimates) is fine.

    Args:
        path: the file to write (its folder is created).
        timestamps: (N,) seconds (or frame indices), array or tensor.
        poses: (N, 4, 4) camera-to-world poses, array or tensor.

    Raises:
        ValueError: wrong shapes, mismatched lengths or non-finite values.
    """
    times = _as_float64(timestamps)
    matrices = _as_float64(poses)
    if times.ndim != 1 or matrices.shape != (len(times), 4, 4):
        raise ValueError(
            f"need (N,) timestamps and (N, 4, 4) poses, got {times.shape} and {matrices.shape}"
        )
    if not (np.isfinite(times).all() and np.isfinite(matrices).all()):
        raise ValueError("timestamps and poses must be finite")
    rotations = orthonormalize_rotation(torch.from_numpy(matrices[:, :3, :3].copy()))
    quaternions = matrix_to_quaternion(rotations).numpy()
    rows = np.concatenate((matrices[:, :3, 3], quaternions), axis=1)
    lines = [TUM_HEADER]
    for time, row in zip(times, rows, strict=True):
        lines.append(" ".join([_number(time), *map(_number, row)]))
    write_text(path, "\n".join(lines) + "\n")


def read_tum_trajectory(
    path: str | Path, allow_missing: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory (``timestamp tx ty tz qx qy qz qw`` per line).

    Blank lines and ``#`` comments are skipped; commas count as spaces. Quaternions
    are normalised (:func:`eslam.io.pose_files.tum_poses`).

    Args:
        path: the file.
        allow_missing: read a line whose pose holds nan or inf as a missing pose (all
            NaN) instead of failing; its timestamp must still be finite.

    Returns:
        timestamps (N,) float64 seconds and poses (N, 4, 4) float64 camera-to-world.

    Raises:
        InputError: naming the file and line, for a missing file, a line without 8
            numbers, a value that is not a finite number, or a zero quaternion.
    """
    return tum_poses(read_pose_table(path, (TUM_COLUMNS,)), allow_missing)


def read_run_trajectories(
    run: str | Path, *needed: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A finished run folder's time stamps, estimate and ground truth: its
    ``trajectory.txt`` and ``trajectory_gt.txt`` (a ground-truth pose the run could not
    score reads as all NaN), row for row.

    Args:
        run: the run folder.
        needed: other files of it the caller reads (e.g. ``map.pt``), checked too.

    Raises:
        InputError: a file missing (named; the fix: a finished run with ground truth),
            or unreadable.
    """
    run = Path(run)
    for name in (RUN_TRAJECTORY, RUN_TRAJECTORY_GT, *needed):
        if not (run / name).is_file():
            raise InputError(
                run / name, "missing", "give the folder of a finished run with ground truth"
            )
    times, estimated = read_tum_trajectory(run / RUN_TRAJECTORY)
    _, truth = read_tum_trajectory(run / RUN_TRAJECTORY_GT, allow_missing=True)
    return times, estimated, truth


def read_trajectory(
    path: str | Path, ground_truth: bool = False, allow_missing: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Read a trajectory in any format we know, told apart by its column count.

    Accepted:
        - a TUM file (8 numbers per line);
        - a Replica ``traj.txt`` (16 numbers per line); timestamps are the line indices
          (0, 1, 2, ...), which is what a run writes for a sequence without time stamps;
        - a run folder: its ``trajectory.txt`` (its ``trajectory_gt.txt`` with
          ``ground_truth``), or a Replica sequence folder (its ``traj.txt``).

    Args:
        path: a file or folder as above.
        ground_truth: in a run folder, read the ground truth, not the estimate.
        allow_missing: read poses holding nan or inf as missing (all NaN) poses
            (ScanNet marks frames without ground truth so) instead of failing.

    Returns:
        timestamps (N,) float64 and poses (N, 4, 4) float64 camera-to-world.

    Raises:
        InputError: a missing path, a folder without a trajectory, or an unknown format.
    """
    path = Path(path)
    if path.is_dir():
        run_file = RUN_TRAJECTORY_GT if ground_truth else RUN_TRAJECTORY
        for name in (run_file, "traj.txt"):
            if (path / name).is_file():
                return read_trajectory(path / name, ground_truth, allow_missing)
        raise InputError(
            path,
            f"holds no {run_file} (run folder) or traj.txt (Replica sequence)",
            "pass a trajectory file or a run folder",
        )
    table = read_pose_table(path, (TUM_COLUMNS, MATRIX_COLUMNS))
    if table.columns == TUM_COLUMNS:
        return tum_poses(table, allow_missing)
    poses = matrix_poses(table, allow_missing)
    return np.arange(len(poses), dtype=np.float64), poses
