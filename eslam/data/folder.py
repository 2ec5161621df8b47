"""A plain folder of registered colour + depth images, for any RGB-D sensor.

Layout::

    ROOT/color/<stem>.png|jpg|jpeg   colour images, all of one size
    ROOT/depth/<stem>.png            16-bit depth, metres = value / depth_scale, 0 = invalid,
                                     registered to the colour image (same size and camera)
    ROOT/intrinsics.yaml             width, height, fx, fy, cx, cy, depth_scale
                                     (optional: distortion, a list that must be all zeros)
    ROOT/poses.txt                   optional ground truth, see below

Colour and depth are paired by file stem (``000123.png`` with ``000123.png``, or
``1305031102.175304.jpg`` with ``1305031102.175304.png``). When every stem is a number
frames are ordered numerically and ``timestamps()`` are those numbers; otherwise they
are ordered by name and the timestamps are the positions 0, 1, 2, ...

The images must be undistorted: a non-zero ``distortion`` in ``intrinsics.yaml`` is an
error (eslam models a pinhole camera; undistort with e.g. OpenCV first).

``poses.txt`` (camera-to-world, OpenCV camera axes x right / y down / z forward, metres;
blank lines and lines starting with ``#`` are skipped) comes in one of two forms, told
apart by the number of values per line:

- primary, TUM style, 8 values ``timestamp tx ty tz qx qy qz qw`` (the format eslam
  writes its own trajectories in): a line belongs to the frame whose numeric stem equals
  its timestamp (within :data:`TIMESTAMP_TOLERANCE`); frames without a line have no
  ground truth (NaN rows in ``gt_poses()``), but at least one frame must match;
- 16 values, a row-major 4x4 matrix per line, one line per frame in frame order.

Without ``poses.txt``, ``gt_poses()`` returns None.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import yaml

from eslam.config import DataConfig
from eslam.data.base import FileSequence, FrameReading, require_dir, require_file
from eslam.data.transform import transform_from_options
from eslam.errors import InputError
from eslam.io.pose_files import (
    MATRIX_COLUMNS,
    TUM_COLUMNS,
    matrix_poses,
    read_pose_table,
    tum_poses,
)
from eslam.types import Intrinsics

INTRINSICS_FILE = "intrinsics.yaml"
POSES_FILE = "poses.txt"

TIMESTAMP_TOLERANCE = 1e-4
"""Largest |stem - timestamp| (same units, seconds or frame numbers) pairing a TUM-style
pose line with a frame; below TUM's 1e-6 s stamp precision times 100."""

_COLOUR_SUFFIXES = (".png", ".jpg", ".jpeg")
_DEPTH_SUFFIXES = (".png",)
_INTRINSICS_KEYS = ("width", "height", "fx", "fy", "cx", "cy", "depth_scale")
_NUMBER_RE = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")


def read_intrinsics_yaml(path: Path) -> tuple[Intrinsics, float]:
    """Read ``intrinsics.yaml``: the camera and the depth scale (units per metre)."""
    require_file(path, f"the camera: {', '.join(_INTRINSICS_KEYS)}")
    fix = f"expected the keys {', '.join(_INTRINSICS_KEYS)} (and optional distortion)"
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as error:
        problem = str(error).replace("\n", " ")
        raise InputError(path, f"not valid YAML ({problem})", fix) from None
    if not isinstance(data, dict):
        raise InputError(path, "must be a mapping of camera parameters", fix)
    missing = [key for key in _INTRINSICS_KEYS if key not in data]
    if missing:
        raise InputError(path, f"missing {', '.join(missing)}", fix)
    unknown = sorted(set(data) - set(_INTRINSICS_KEYS) - {"distortion"})
    if unknown:
        raise InputError(path, f"unknown key(s) {', '.join(map(str, unknown))}", fix)
    try:
        # Numbers are parsed explicitly: PyYAML reads 1e-3 as a string.
        values = {key: float(data[key]) for key in _INTRINSICS_KEYS}
        distortion = [float(v) for v in (data.get("distortion") or [])]
        if values["width"] != int(values["width"]) or values["height"] != int(values["height"]):
            raise ValueError("width and height must be whole numbers")
        intrinsics = Intrinsics(
            int(values["width"]),
            int(values["height"]),
            values["fx"],
            values["fy"],
            values["cx"],
            values["cy"],
        )
    except (TypeError, ValueError) as error:
        raise InputError(path, f"invalid camera parameters ({error})", fix) from None
    if any(distortion):
        raise InputError(
            path,
            f"non-zero distortion {distortion}: eslam reads pinhole images",
            "undistort the images first (e.g. cv2.undistort) and set distortion to zeros",
        )
    scale = values["depth_scale"]
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(path, f"depth_scale must be positive, got {scale:g}", fix)
    return intrinsics, scale


def _stem_files(folder: Path, suffixes: tuple[str, ...]) -> dict[str, Path]:
    files: dict[str, Path] = {}
    for path in folder.iterdir():
        if path.is_file() and path.suffix.lower() in suffixes:
            if path.stem in files:
                raise InputError(
                    path, f"has the same stem as {files[path.stem].name}", "keep one of them"
                )
            files[path.stem] = path
    return files


def _order(stems: Iterable[str]) -> tuple[list[str], np.ndarray]:
    """Stems in frame order and their timestamps (the numbers, or positions)."""
    stems = list(stems)
    if all(_NUMBER_RE.match(stem) for stem in stems):
        ordered = sorted(stems, key=float)
        return ordered, np.array([float(s) for s in ordered], dtype=np.float64)
    ordered = sorted(stems)
    return ordered, np.arange(len(ordered), dtype=np.float64)


def read_folder_poses(path: Path, timestamps: np.ndarray, numeric_stems: bool) -> np.ndarray:
    """(N, 4, 4) float64 poses of the N frames with ``timestamps``; NaN where none matches.

    Args:
        path: the poses file.
        timestamps: (N,) the frames' timestamps (TUM-style lines are matched to them).
        numeric_stems: whether the timestamps are the file stems (else TUM-style lines
            cannot be matched and are an error).

    Raises:
        InputError: bad lines, non-rigid or non-finite poses, a 4x4 file whose line count
            is not the frame count, or a TUM-style file that matches no frame.
    """
    table = read_pose_table(path, (TUM_COLUMNS, MATRIX_COLUMNS))
    if table.columns == MATRIX_COLUMNS:
        if len(table.lines) != len(timestamps):
            raise InputError(
                path,
                f"has {len(table.lines)} 4x4 poses for {len(timestamps)} frames",
                "write one pose per frame, in frame order (or use timestamped TUM lines)",
            )
        return matrix_poses(table)
    if not numeric_stems:
        raise InputError(
            path,
            "timestamped pose lines need image files named by number or timestamp",
            "rename the images (e.g. 000123.png) or write one 4x4 pose per line",
        )
    times, tum = tum_poses(table)
    poses = np.full((len(timestamps), 4, 4), np.nan)
    for time, pose in zip(times, tum, strict=True):
        nearest = int(np.argmin(np.abs(timestamps - time)))
        if abs(timestamps[nearest] - time) <= TIMESTAMP_TOLERANCE:
            poses[nearest] = pose
    if np.isnan(poses).all():
        raise InputError(
            path,
            f"no line's timestamp matches a frame stem (frames {timestamps[0]:.17g} to "
            f"{timestamps[-1]:.17g})",
            "the first value of each line must equal the image file's stem",
        )
    return poses


class FolderSequence(FileSequence):
    """Reader of a plain colour/depth folder (see the module docstring).

    Args:
        root: the folder holding ``color/``, ``depth/``, ``intrinsics.yaml`` and
            optionally ``poses.txt``.
        options: the ``data`` config section; depth_scale (default: intrinsics.yaml's),
            resize and crop (default: none) apply.

    Raises:
        InputError: missing folder or file, a colour image without its depth partner
            (or back), bad intrinsics (non-zero distortion included), images whose size
            is not the intrinsics', or bad poses.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = require_dir(Path(root), "color/, depth/ and intrinsics.yaml")
        colour_dir = require_dir(self.root / "color", "colour images (.png/.jpg)")
        depth_dir = require_dir(self.root / "depth", "16-bit depth .png images")
        self.raw_intrinsics, file_scale = read_intrinsics_yaml(self.root / INTRINSICS_FILE)
        self.depth_scale = options.depth_scale or file_scale
        self.transform = transform_from_options(options.resize, options.crop)
        self.reading = FrameReading(self.raw_intrinsics, self.depth_scale, self.transform)
        self.intrinsics = self.reading.intrinsics
        colour = _stem_files(colour_dir, _COLOUR_SUFFIXES)
        depth = _stem_files(depth_dir, _DEPTH_SUFFIXES)
        if not colour and not depth:
            raise InputError(colour_dir, "holds no colour images (.png/.jpg)")
        for lone, partners, folder in ((colour, depth, depth_dir), (depth, colour, colour_dir)):
            for stem in sorted(set(lone) - set(partners)):
                raise InputError(
                    lone[stem],
                    f"has no partner {folder.name}/{stem}.* "
                    f"({len(colour)} colour vs {len(depth)} depth images)",
                    "colour and depth images are paired by file name",
                )
        self.numeric_stems = all(_NUMBER_RE.match(stem) for stem in colour)
        self.stems, self._times = _order(colour)
        self._colour_paths = [colour[s] for s in self.stems]
        self._depth_paths = [depth[s] for s in self.stems]
        poses_path = self.root / POSES_FILE
        self._poses = (
            read_folder_poses(poses_path, self._times, self.numeric_stems)
            if poses_path.exists()
            else None
        )
