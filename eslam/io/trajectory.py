"""Trajectory files: TUM (read and write), Replica ``traj.txt`` and run folders (read).

TUM format (the one ``trajectory.txt`` of a run folder uses): one pose per line,
``timestamp tx ty tz qx qy qz qw``, camera-to-world, translation in metres, quaternion
scalar-last; lines starting with ``#`` are comments. Our poses are camera-to-world in
OpenCV camera axes, and so are the TUM ground-truth files (the optical frame), so no
axis conversion happens here.

Numbers are written with Python's shortest round-trip representation, so reading a
file back gives the very float64 values written: poses survive a round trip to
rounding of the quaternion conversion (about 1e-15).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from eslam.atomic import write_text
from eslam.data.base import check_pose
from eslam.data.replica import read_traj
from eslam.errors import InputError
from eslam.geometry.rotation import (
    matrix_to_quaternion,
    orthonormalize_rotation,
    quaternion_to_matrix,
)

TUM_HEADER = "# timestamp tx ty tz qx qy qz qw (camera-to-world, OpenCV camera axes, metres)"
"""First line of every TUM file we write (readers skip ``#`` comments)."""
TUM_COLUMNS = 8
"""Numbers per line of a TUM trajectory."""
REPLICA_COLUMNS = 16
"""Numbers per line of a Replica ``traj.txt`` (a row-major 4x4 camera-to-world pose)."""
RUN_TRAJECTORY = "trajectory.txt"
"""Estimated trajectory of a run folder (see :mod:`eslam.io.run_dir`)."""
RUN_TRAJECTORY_GT = "trajectory_gt.txt"
"""Ground-truth trajectory of a run folder (see :mod:`eslam.io.run_dir`)."""
_MIN_QUATERNION_NORM = 1e-12


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


def _data_lines(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, fields) of every non-blank, non-comment line."""
    if not path.is_file():
        problem = "is a folder, not a trajectory file" if path.is_dir() else "not found"
        raise InputError(path, problem)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(path, f"cannot be read as text ({error})") from None
    lines = []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            lines.append((number, stripped.replace(",", " ").split()))
    if not lines:
        raise InputError(path, "holds no poses")
    return lines


def _parse_numbers(
    path: Path, number: int, fields: list[str], allow_missing: bool = False
) -> list[float]:
    values = []
    for field in fields:
        try:
            values.append(float(field))
        except ValueError:
            raise InputError(path, f"line {number}: '{field}' is not a number") from None
    if not allow_missing and not all(np.isfinite(values)):
        raise InputError(
            path,
            f"line {number}: holds a non-finite value (nan or inf)",
            "fix that pose, or pass allow_missing=True to read it as a missing pose",
        )
    return values


def read_tum_trajectory(
    path: str | Path, allow_missing: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory (``timestamp tx ty tz qx qy qz qw`` per line).

    Blank lines and ``#`` comments are skipped; commas count as spaces. Quaternions
    are normalised.

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
    path = Path(path)
    rows = []
    for number, fields in _data_lines(path):
        if len(fields) != TUM_COLUMNS:
            raise InputError(
                path,
                f"line {number}: expected 8 numbers (timestamp tx ty tz qx qy qz qw), "
                f"got {len(fields)}",
            )
        values = _parse_numbers(path, number, fields, allow_missing)
        if not np.isfinite(values[0]):
            raise InputError(path, f"line {number}: the timestamp is not finite")
        finite = all(np.isfinite(values))
        if finite and np.linalg.norm(values[4:]) < _MIN_QUATERNION_NORM:
            raise InputError(path, f"line {number}: the quaternion is zero")
        rows.append(values if finite else [values[0], *([np.nan] * 7)])
    table = np.array(rows, dtype=np.float64)
    missing = ~np.isfinite(table[:, 1:]).all(axis=1)
    quaternions = table[:, 4:].copy()
    quaternions[missing] = [0.0, 0.0, 0.0, 1.0]
    quaternions /= np.linalg.norm(quaternions, axis=1, keepdims=True)
    poses = np.tile(np.eye(4), (len(table), 1, 1))
    poses[:, :3, :3] = quaternion_to_matrix(torch.from_numpy(quaternions)).numpy()
    poses[:, :3, 3] = table[:, 1:4]
    poses[missing] = np.nan
    return table[:, 0].copy(), poses


def _read_replica_with_missing(path: Path) -> np.ndarray:
    """A Replica ``traj.txt`` whose non-finite lines become all-NaN (missing) poses."""
    poses = []
    for number, fields in _data_lines(path):
        if len(fields) != REPLICA_COLUMNS:
            raise InputError(path, f"line {number}: expected 16 numbers, got {len(fields)}")
        pose = np.array(_parse_numbers(path, number, fields, True)).reshape(4, 4)
        if np.isfinite(pose).all():
            poses.append(check_pose(pose, path, f"line {number}"))
        else:
            poses.append(np.full((4, 4), np.nan))
    return np.stack(poses)


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
    number, fields = _data_lines(path)[0]
    if len(fields) == TUM_COLUMNS:
        return read_tum_trajectory(path, allow_missing)
    if len(fields) == REPLICA_COLUMNS:
        poses = _read_replica_with_missing(path) if allow_missing else read_traj(path)
        return np.arange(len(poses), dtype=np.float64), poses
    raise InputError(
        path,
        f"line {number}: {len(fields)} columns, not a known trajectory format",
        "expected 8 numbers per line (TUM: timestamp tx ty tz qx qy qz qw) or 16 "
        "(Replica traj.txt: a row-major 4x4 camera-to-world pose)",
    )
