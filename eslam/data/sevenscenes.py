"""Microsoft 7-Scenes, in its native per-sequence layout.

Layout::

    ROOT/frame-000000.color.png|jpg   colour, 640x480
    ROOT/frame-000000.depth.png       uint16 depth, millimetres; 0 and 65535 are invalid
    ROOT/frame-000000.pose.txt        4x4 camera-to-world, OpenCV axes, metres
    ROOT/camera-intrinsics.txt        optional 3x3 K (in ROOT or its parent folder)

The official release holds one folder per recording, ``SCENE/seq-01/frame-...``: pass
one ``seq-XX`` folder as the data path (a folder holding only ``seq-XX`` subfolders is
refused with that advice; recordings are separate trajectories and are not chained).
The official release ships no intrinsics file: without ``camera-intrinsics.txt`` the
published values apply (:data:`SEVENSCENES_INTRINSICS`).

Caveats of the data, handled here:

- Depth 65535 marks invalid pixels as well as 0; both become 0.
- Ground truth comes from KinectFusion; its rotation blocks are orthonormal only to
  about 4e-4. Each is replaced by the nearest rotation (SVD) after checking that it is
  close to one (:data:`ROTATION_TOLERANCE`), so a grossly broken pose is still an error.
- Colour and depth are NOT registered: two cameras about 2.5 cm apart with different
  focal lengths (585 depth, about 525 colour). Read with the depth camera's K, colour
  lies tens of pixels off the geometry (redkitchen: median 22, largest 55 px). With
  ``data.register_colour`` (the default) each colour image is resampled into the depth
  camera
  (:func:`eslam.data.registration.register_colour`, :data:`SEVENSCENES_COLOUR_CAMERA`,
  fitted by ``benchmarks/colour_registration.py``).

Frames are ordered by their number (gaps allowed); timestamps are the frame numbers.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import torch

from eslam.config import DataConfig
from eslam.data.base import FileSequence, FrameReading, require_dir
from eslam.data.registration import ColourCamera, register_colour
from eslam.data.scannet import fitting_intrinsics, image_size
from eslam.data.transform import transform_from_options
from eslam.errors import InputError
from eslam.geometry.rotation import orthonormalize_rotation
from eslam.io.pose_files import check_pose, read_matrix_file
from eslam.types import Intrinsics

SEVENSCENES_DEPTH_SCALE = 1000.0
"""7-Scenes depth PNG units per metre (millimetres; dataset page)."""

SEVENSCENES_INVALID_DEPTH = 65535
"""Raw depth value 7-Scenes uses, besides 0, for pixels without depth (shared/data README)."""

SEVENSCENES_INTRINSICS = Intrinsics(640, 480, 585.0, 585.0, 320.0, 240.0)
"""The depth camera published on the 7-Scenes page (fx = fy = 585, cx = 320, cy = 240)."""

SEVENSCENES_COLOUR_CAMERA = ColourCamera(
    fx=525.0, fy=525.0, cx=320.0, cy=239.0, centre=(0.025, 0.0, 0.0)
)
"""The Kinect v1 colour camera relative to the depth camera of 7-Scenes: the usual
525-pixel focal length of 7-Scenes colour, its centre 2.5 cm along +x, row 239. How
well it aligns colour with depth on redkitchen, against the raw colour and a fitted
camera: ``benchmarks/colour_registration.py`` (docs/results.md, "Data checks")."""

ROTATION_TOLERANCE = 1e-2
"""Largest |R^T R - I| entry (and |det R - 1|) of a raw 7-Scenes rotation before it is
re-orthonormalised; the dataset's own are within ~4e-4."""

INTRINSICS_FILE = "camera-intrinsics.txt"

_FRAME_RE = re.compile(r"^frame-(\d+)\.(color|depth|pose)\.(png|jpg|jpeg|txt)$", re.IGNORECASE)
_SEQUENCE_RE = re.compile(r"^seq-\d+$", re.IGNORECASE)


def read_intrinsics_file(path: Path, size: tuple[int, int]) -> Intrinsics:
    """Read ``camera-intrinsics.txt`` (3x3 K) for images of ``size`` (width, height)."""
    k = read_matrix_file(path, "a 3x3 camera matrix", (3, 3))
    return fitting_intrinsics(path, (k[0, 0], k[1, 1], k[0, 2], k[1, 2]), size)


def find_intrinsics(root: Path, size: tuple[int, int]) -> Intrinsics:
    """Intrinsics from ``camera-intrinsics.txt`` in ``root`` or its parent, else the published.

    Args:
        root: the recording folder.
        size: (width, height) of its depth images.
    """
    for folder in (root, root.parent):
        path = folder / INTRINSICS_FILE
        if path.is_file():
            return read_intrinsics_file(path, size)
    return SEVENSCENES_INTRINSICS


def rotation_error(rotation: np.ndarray) -> float:
    """max(|R^T R - I|, |det R - 1|) of a (3, 3) matrix: 0 for a rotation."""
    orthogonality = np.abs(rotation.T @ rotation - np.eye(3)).max()
    return float(max(orthogonality, abs(np.linalg.det(rotation) - 1.0)))


def read_sevenscenes_pose(path: Path) -> np.ndarray:
    """(4, 4) float64 camera-to-world pose of ``frame-N.pose.txt``, rotation made orthonormal.

    Raises:
        InputError: not 16 numbers, non-finite, or a rotation off by more than
            :data:`ROTATION_TOLERANCE`.
    """
    pose = read_matrix_file(path, "a 4x4 camera-to-world pose")
    if not np.all(np.isfinite(pose)):
        check_pose(pose, path, "pose")  # raises the shared non-finite error
    error = rotation_error(pose[:3, :3])
    if error > ROTATION_TOLERANCE:
        raise InputError(
            path,
            f"pose is not a rigid transform (rotation off by {error:.2g}, "
            f"tolerance {ROTATION_TOLERANCE:g})",
            "poses must be camera-to-world rotations plus translations",
        )
    pose[:3, :3] = orthonormalize_rotation(torch.from_numpy(pose[:3, :3])).numpy()
    return check_pose(pose, path, "pose")


def _frame_files(root: Path) -> dict[str, dict[int, Path]]:
    files: dict[str, dict[int, Path]] = {"color": {}, "depth": {}, "pose": {}}
    for path in root.iterdir():
        match = _FRAME_RE.match(path.name)
        if match:
            files[match.group(2).lower()][int(match.group(1))] = path
    return files


def _refuse_scene_folder(root: Path) -> None:
    sequences = sorted(p.name for p in root.iterdir() if p.is_dir() and _SEQUENCE_RE.match(p.name))
    if sequences:
        raise InputError(
            root,
            f"holds recordings {', '.join(sequences)} but no frame-*.color.png files",
            f"pass one recording as the data path, e.g. {root / sequences[0]}",
        )
    raise InputError(root, "holds no frame-XXXXXX.color.png / .depth.png / .pose.txt files")


class SevenScenesSequence(FileSequence):
    """Reader of one 7-Scenes recording (see the module docstring).

    Args:
        root: the folder of ``frame-XXXXXX.*`` files (a ``seq-XX`` folder).
        options: the ``data`` config section; depth_scale (default 1000), resize and
            crop (default: none) and register_colour (default: on) apply.

    Raises:
        InputError: missing folder, a frame without its colour, depth or pose file, a
            bad pose, bad intrinsics file, images of the wrong size, or colour
            registration asked for images that are not 640x480.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = require_dir(Path(root), "a 7-Scenes recording: frame-XXXXXX.* files")
        files = _frame_files(self.root)
        if not files["color"] and not files["depth"]:
            _refuse_scene_folder(self.root)
        for kind, other in (("color", "depth"), ("depth", "color"), ("color", "pose")):
            for number in sorted(set(files[kind]) - set(files[other])):
                suffix = "pose.txt" if other == "pose" else f"{other}.png"
                raise InputError(
                    files[kind][number],
                    f"has no partner frame-{number:06d}.{suffix} "
                    f"({len(files[kind])} {kind} vs {len(files[other])} {other} files)",
                    "every frame needs a colour, a depth and a pose file",
                )
        self.numbers = sorted(files["color"])
        self._times = np.array(self.numbers, dtype=np.float64)
        self._colour_paths = [files["color"][n] for n in self.numbers]
        self._depth_paths = [files["depth"][n] for n in self.numbers]
        self.raw_intrinsics = find_intrinsics(self.root, image_size(self._depth_paths[0]))
        if options.register_colour and self.raw_intrinsics.size != SEVENSCENES_INTRINSICS.size:
            raise InputError(
                self._depth_paths[0],
                f"is {self.raw_intrinsics.width}x{self.raw_intrinsics.height}; 7-Scenes colour "
                "registration knows the 640x480 Kinect v1 only",
                "set data.register_colour=false to use the colour as it is",
            )
        self.depth_scale = options.depth_scale or SEVENSCENES_DEPTH_SCALE
        self.transform = transform_from_options(options.resize, options.crop)
        self.reading = FrameReading(
            self.raw_intrinsics,
            self.depth_scale,
            self.transform,
            invalid_depth=SEVENSCENES_INVALID_DEPTH,
            prepare=self._registered if options.register_colour else None,
        )
        self.intrinsics = self.reading.intrinsics
        self._poses = np.stack([read_sevenscenes_pose(files["pose"][n]) for n in self.numbers])

    def _registered(self, rgb: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(colour resampled into the depth camera, depth): ``FrameReading.prepare``."""
        return register_colour(rgb, depth, self.raw_intrinsics, SEVENSCENES_COLOUR_CAMERA), depth
