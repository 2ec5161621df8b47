"""Text files of poses: the one parser every trajectory and dataset pose reader uses.

A pose file holds one pose per line in one of two layouts, told apart by the number of
values on a line:

- TUM, 8 numbers ``timestamp tx ty tz qx qy qz qw`` (TUM RGB-D "file formats" page):
  translation in metres, quaternion scalar-last; R = quaternion_to_matrix(q / |q|).
  Run folders' trajectory.txt, TUM groundtruth.txt, the folder layout's poses.txt.
- matrix, 16 numbers: a row-major 4x4 camera-to-world matrix (Replica ``traj.txt``,
  the folder layout's poses.txt).

Blank lines and lines starting with ``#`` are skipped; commas count as spaces. Poses
are camera-to-world in OpenCV camera axes in every layout eslam reads, so nothing here
converts axes. Files holding a single matrix (ScanNet ``pose/N.txt``, 7-Scenes
``frame-N.pose.txt``, camera matrices) are read by :func:`read_matrix_file`. Every
error is an :class:`~eslam.errors.InputError` naming the file and the line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from eslam.errors import InputError
from eslam.geometry.pose import pose_from_quaternion_translation

TUM_COLUMNS = 8
"""Numbers per line of a TUM pose file: timestamp tx ty tz qx qy qz qw."""
MATRIX_COLUMNS = 16
"""Numbers per line of a matrix pose file: a row-major 4x4 camera-to-world pose."""
LAYOUTS = {
    TUM_COLUMNS: "'timestamp tx ty tz qx qy qz qw'",
    MATRIX_COLUMNS: "row-major 4x4 camera-to-world pose",
}
"""What one line of each layout holds, by its number of values (named in errors)."""
RIGID_TOLERANCE = 1e-3
"""Largest |R^T R - I| entry (and |det R - 1|) accepted for a ground-truth rotation."""
MIN_QUATERNION_NORM = 1e-12
"""A quaternion shorter than this has no direction to normalise: not a rotation."""


def text_lines(path: str | Path) -> list[tuple[int, str]]:
    """(line number, stripped text) of every line that is neither blank nor a ``#`` comment.

    Raises:
        InputError: the file is missing, is a folder, or is not UTF-8 text.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "is a folder, not a text file" if path.is_dir() else "not found")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(path, f"not a text file ({error})") from None
    lines = []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            lines.append((number, stripped))
    return lines


@dataclass(frozen=True, eq=False)
class PoseTable:
    """The pose lines of a file as numbers.

    Attributes:
        path: the file.
        lines: the line number (1-based) of each row, for error messages.
        values: (N, C) float64, C = TUM_COLUMNS or MATRIX_COLUMNS.
    """

    path: Path
    lines: tuple[int, ...]
    values: np.ndarray

    @property
    def columns(self) -> int:
        """Numbers per line: TUM_COLUMNS or MATRIX_COLUMNS."""
        return int(self.values.shape[1])


def _numbers(path: Path, number: int, fields: list[str]) -> list[float]:
    values = []
    for field in fields:
        try:
            values.append(float(field))
        except ValueError:
            raise InputError(
                path, f"line {number}: not a list of numbers ('{field}' is not a number)"
            ) from None
    return values


def read_pose_table(
    path: str | Path, columns: Sequence[int] = (TUM_COLUMNS, MATRIX_COLUMNS)
) -> PoseTable:
    """Read the pose lines of ``path``: every line holds the same count, one of ``columns``.

    Raises:
        InputError: naming the file and line, for a missing file, a value that is not a
            number, a line with another count of values, or a file without pose lines.
    """
    path = Path(path)
    numbers: list[int] = []
    rows: list[list[float]] = []
    for number, text in text_lines(path):
        values = _numbers(path, number, text.replace(",", " ").split())
        allowed = (len(rows[0]),) if rows else tuple(columns)
        if len(values) not in allowed:
            counts = " or ".join(str(count) for count in allowed)
            layouts = " or one ".join(LAYOUTS[count] for count in allowed)
            raise InputError(
                path,
                f"line {number}: expected {counts} numbers, got {len(values)}",
                f"write one {layouts} per line",
            )
        numbers.append(number)
        rows.append(values)
    if not rows:
        raise InputError(path, "holds no poses")
    return PoseTable(path, tuple(numbers), np.array(rows, dtype=np.float64))


def _non_finite(source: Path, label: str) -> InputError:
    return InputError(
        source, f"{label}: pose has non-finite values (nan or inf)", "remove or fix that pose"
    )


def check_pose(pose: np.ndarray, source: Path, label: str) -> np.ndarray:
    """Check that ``pose`` is a finite rigid 4x4 transform; return it as float64.

    Rigid: |R^T R - I| and |det R - 1| within RIGID_TOLERANCE, last row exactly 0 0 0 1.

    Args:
        pose: (4, 4) camera-to-world matrix.
        source: the file the pose came from, named in the error.
        label: where in the file (e.g. "line 12"), named in the error.
    """
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4):
        raise InputError(source, f"{label}: pose must be 4x4, got shape {pose.shape}")
    if not np.all(np.isfinite(pose)):
        raise _non_finite(source, label)
    rotation = pose[:3, :3]
    orthogonality = np.abs(rotation.T @ rotation - np.eye(3)).max()
    determinant = np.linalg.det(rotation)
    bottom = np.abs(pose[3] - np.array([0.0, 0.0, 0.0, 1.0])).max()
    if orthogonality > RIGID_TOLERANCE or abs(determinant - 1.0) > RIGID_TOLERANCE or bottom > 0:
        raise InputError(
            source,
            f"{label}: pose is not a rigid transform (|R^T R - I| = {orthogonality:.2g}, "
            f"det R = {determinant:.4g}, last row {pose[3].tolist()})",
            "poses must be camera-to-world rotations plus translations",
        )
    return pose


def tum_poses(
    table: PoseTable, allow_missing: bool = False, quaternion_tolerance: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Timestamps and camera-to-world poses of TUM lines: [[R(q / |q|), t], [0, 1]].

    Args:
        table: TUM_COLUMNS values per line.
        allow_missing: read a line whose pose holds nan or inf as a missing pose (all
            NaN) instead of failing; its timestamp must still be finite.
        quaternion_tolerance: largest accepted | |q| - 1 |; None accepts any quaternion
            longer than MIN_QUATERNION_NORM (it is normalised).

    Returns:
        timestamps (N,) float64 seconds and poses (N, 4, 4) float64.

    Raises:
        InputError: naming the line of a non-finite timestamp, a non-finite pose (unless
            ``allow_missing``) or a quaternion that is not a rotation.
    """
    if table.columns != TUM_COLUMNS:
        raise ValueError(f"need {TUM_COLUMNS} values per line, got {table.columns}")
    values = table.values
    missing = ~np.isfinite(values[:, 1:]).all(axis=1)
    norms = np.linalg.norm(np.where(missing[:, None], 1.0, values[:, 4:]), axis=1)
    for row, number in enumerate(table.lines):
        if not math.isfinite(values[row, 0]):
            raise InputError(table.path, f"line {number}: the timestamp is not finite")
        if missing[row]:
            if allow_missing:
                continue
            raise _non_finite(table.path, f"line {number}")
        off = quaternion_tolerance is not None and abs(norms[row] - 1.0) > quaternion_tolerance
        if norms[row] < MIN_QUATERNION_NORM or off:
            raise InputError(
                table.path,
                f"line {number}: quaternion qx qy qz qw has norm {norms[row]:.4g} "
                "and is not a rotation",
                "write unit quaternions, scalar last",
            )
    quaternions = np.where(missing[:, None], [0.0, 0.0, 0.0, 1.0], values[:, 4:]) / norms[:, None]
    translations = np.where(missing[:, None], 0.0, values[:, 1:4])
    poses = pose_from_quaternion_translation(
        torch.from_numpy(quaternions), torch.from_numpy(translations)
    ).numpy()
    poses[missing] = np.nan
    return values[:, 0].copy(), poses


def matrix_poses(table: PoseTable, allow_missing: bool = False) -> np.ndarray:
    """(N, 4, 4) float64 camera-to-world poses of matrix lines, each checked rigid.

    Args:
        table: MATRIX_COLUMNS values per line.
        allow_missing: read a line holding nan or inf as a missing pose (all NaN)
            instead of failing (ScanNet marks frames without ground truth so).

    Raises:
        InputError: naming the line of a non-finite (unless ``allow_missing``) or
            non-rigid pose.
    """
    if table.columns != MATRIX_COLUMNS:
        raise ValueError(f"need {MATRIX_COLUMNS} values per line, got {table.columns}")
    poses = table.values.reshape(-1, 4, 4).copy()
    for row, number in enumerate(table.lines):
        if allow_missing and not np.isfinite(poses[row]).all():
            poses[row] = np.nan
        else:
            poses[row] = check_pose(poses[row], table.path, f"line {number}")
    return poses


def read_matrix_file(path: str | Path, what: str, shape: tuple[int, int] = (4, 4)) -> np.ndarray:
    """Read a file holding one whitespace-separated matrix of ``shape`` as float64.

    Non-finite entries (ScanNet's ``-inf`` poses) are kept; the caller decides what they
    mean.

    Args:
        path: the file.
        what: what it should hold (e.g. "a 4x4 camera-to-world pose"), named in errors.
        shape: (rows, columns) of the matrix.

    Raises:
        InputError: a missing file, text that is not numbers, or another count of numbers.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, f"file not found (expected {what})")
    try:
        values = [float(value) for value in path.read_text(encoding="utf-8").split()]
    except ValueError:
        raise InputError(path, "not a list of numbers", f"expected {what}") from None
    except UnicodeDecodeError:
        raise InputError(path, "not a text file", f"expected {what}") from None
    rows, cols = shape
    if len(values) != rows * cols:
        raise InputError(
            path, f"expected {rows * cols} numbers (a {rows}x{cols} matrix), got {len(values)}"
        )
    return np.array(values, dtype=np.float64).reshape(shape)
