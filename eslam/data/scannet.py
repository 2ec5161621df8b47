"""ScanNet, in the layout ScanNet's SensReader exports a ``.sens`` file to.

Layout::

    ROOT/color/N.jpg                      colour (typically 1296x968), N = 0, 1, 2, ...
    ROOT/depth/N.png                      uint16 depth, millimetres (typically 640x480)
    ROOT/pose/N.txt                       4x4 camera-to-world, OpenCV axes, metres
    ROOT/intrinsic/intrinsic_depth.txt    4x4, the depth camera's K in its top-left 3x3
    ROOT/intrinsic/intrinsic_color.txt    4x4, the colour camera's K (not used)

Frame numbers are the file stems, not zero-padded: frames are ordered numerically and
may have gaps. Colour is resized to the depth image size and the depth camera's
intrinsics apply to both (as in the ESLAM release, which treats the resized colour as
registered to depth). ``intrinsic/intrinsic_depth.txt`` is used when present; it is
per scene (e.g. scene0000_00: fx 577.590698 fy 578.729797 cx 318.905426 cy 242.683609,
the values the release hard-codes for every scene). Without it the release's values
(:data:`RELEASE_DEPTH_INTRINSICS`) apply. By default 10 pixels are cropped on every
border (the release's ``crop_edge``), where ScanNet's depth is least reliable.

ScanNet marks frames where its tracking was lost with a ``-inf`` pose matrix: any
non-finite pose is read as "no ground truth" (a NaN row in :meth:`gt_poses`, ``pose_gt``
None), not an error. A finite pose that is not rigid is an error.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from eslam.config import DataConfig
from eslam.data.base import FileSequence, FrameReading, require_dir
from eslam.data.transform import transform_from_options
from eslam.errors import InputError
from eslam.io.pose_files import check_pose, read_matrix_file
from eslam.types import Intrinsics

SCANNET_DEPTH_SCALE = 1000.0
"""ScanNet depth PNG units per metre (millimetres; docs/method.md section 9)."""

SCANNET_CROP = 10
"""Pixels cropped on every border by default (release config ``cam.crop_edge``)."""

RELEASE_DEPTH_INTRINSICS = (577.590698, 578.729797, 318.905426, 242.683609)
"""fx, fy, cx, cy of the ESLAM release's ScanNet config (scene0000_00's depth camera,
docs/method.md section 9), used when a scene has no ``intrinsic/intrinsic_depth.txt``."""

PRINCIPAL_POINT_BAND = 0.25
"""The principal point must lie within this fraction of the image size from the image
centre; otherwise the intrinsics are for another image size (e.g. the colour camera's)."""

_COLOUR_RE = re.compile(r"^(\d+)\.(?:jpg|jpeg|png)$", re.IGNORECASE)
_DEPTH_RE = re.compile(r"^(\d+)\.png$", re.IGNORECASE)
_POSE_RE = re.compile(r"^(\d+)\.txt$", re.IGNORECASE)


def fitting_intrinsics(
    path: Path, k: tuple[float, float, float, float], size: tuple[int, int]
) -> Intrinsics:
    """Intrinsics ``k`` = (fx, fy, cx, cy) read from ``path`` for images of ``size``.

    Raises:
        InputError: non-finite or non-positive focal lengths, or a principal point
            farther than :data:`PRINCIPAL_POINT_BAND` from the image centre (the K of
            another image size, e.g. the colour camera's).
    """
    fx, fy, cx, cy = k
    width, height = size
    off_centre = (
        abs(cx - (width - 1) / 2) > PRINCIPAL_POINT_BAND * width
        or abs(cy - (height - 1) / 2) > PRINCIPAL_POINT_BAND * height
    )
    if not np.all(np.isfinite(np.array(k))) or fx <= 0 or fy <= 0 or off_centre:
        raise InputError(
            path,
            f"intrinsics fx {fx:g} fy {fy:g} cx {cx:g} cy {cy:g} do not fit the "
            f"{width}x{height} depth images",
            "the file must hold the depth camera's K for that image size",
        )
    return Intrinsics(width, height, float(fx), float(fy), float(cx), float(cy))


def depth_intrinsics(path: Path, size: tuple[int, int]) -> Intrinsics:
    """The depth camera of ``intrinsic_depth.txt`` for depth images of ``size`` (w, h).

    Falls back to :data:`RELEASE_DEPTH_INTRINSICS` when the file does not exist.
    """
    if not path.exists():
        return fitting_intrinsics(path, RELEASE_DEPTH_INTRINSICS, size)
    matrix = read_matrix_file(path, "the depth camera's 4x4 intrinsic matrix")
    return fitting_intrinsics(path, (matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2]), size)


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) of an image, from its header."""
    try:
        with Image.open(path) as image:
            return image.size
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as error:
        raise InputError(path, f"unreadable image ({error})", "re-export the image") from None


def _numbered_files(folder: Path, pattern: re.Pattern[str]) -> dict[int, Path]:
    files: dict[int, Path] = {}
    for path in folder.iterdir():
        match = pattern.match(path.name)
        if match:
            files[int(match.group(1))] = path
    return files


def _check_partners(first: dict[int, Path], second: dict[int, Path], second_folder: Path) -> None:
    """Raise naming the first file of ``first`` without a partner in ``second``."""
    for number in sorted(set(first) - set(second)):
        raise InputError(
            first[number],
            f"has no partner {second_folder.name}/{number}.* ({len(first)} vs {len(second)} files)",
            f"every frame needs a file in color/, depth/ and pose/ ({second_folder})",
        )


def read_scannet_pose(path: Path) -> np.ndarray:
    """(4, 4) float64 camera-to-world pose of ``pose/N.txt``; all NaN where it is non-finite."""
    pose = read_matrix_file(path, "a 4x4 camera-to-world pose")
    if not np.all(np.isfinite(pose)):
        return np.full((4, 4), np.nan)
    return check_pose(pose, path, "pose")


class ScanNetSequence(FileSequence):
    """Reader of a ScanNet scene exported by SensReader (see the module docstring).

    Args:
        root: the scene folder (holding ``color/``, ``depth/``, ``pose/``, ``intrinsic/``).
        options: the ``data`` config section; depth_scale (default 1000), resize (default:
            none; applied after the colour is brought to the depth size) and crop
            (default 10) apply.

    Raises:
        InputError: missing folders or files, a frame without colour, depth or pose,
            a finite non-rigid pose, or intrinsics that do not fit the depth images.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = require_dir(Path(root), "a ScanNet scene: color/, depth/, pose/, intrinsic/")
        folders = {
            name: require_dir(self.root / name, what)
            for name, what in (
                ("color", "N.jpg colour images"),
                ("depth", "N.png depth images"),
                ("pose", "N.txt camera-to-world poses"),
            )
        }
        colour = _numbered_files(folders["color"], _COLOUR_RE)
        depth = _numbered_files(folders["depth"], _DEPTH_RE)
        poses = _numbered_files(folders["pose"], _POSE_RE)
        if not colour and not depth:
            raise InputError(folders["color"], "holds no N.jpg colour images")
        _check_partners(colour, depth, folders["depth"])
        _check_partners(depth, colour, folders["color"])
        _check_partners(colour, poses, folders["pose"])
        self.numbers = sorted(colour)
        self._times = np.array(self.numbers, dtype=np.float64)
        self._colour_paths = [colour[n] for n in self.numbers]
        self._depth_paths = [depth[n] for n in self.numbers]
        self.depth_scale = options.depth_scale or SCANNET_DEPTH_SCALE
        self.raw_intrinsics = depth_intrinsics(
            self.root / "intrinsic" / "intrinsic_depth.txt", image_size(self._depth_paths[0])
        )
        self.transform = transform_from_options(
            options.resize, options.crop, default_crop=SCANNET_CROP
        )
        self.reading = FrameReading(
            self.raw_intrinsics, self.depth_scale, self.transform, colour_any_size=True
        )
        self.intrinsics = self.reading.intrinsics
        self._poses = np.stack([read_scannet_pose(poses[n]) for n in self.numbers])
