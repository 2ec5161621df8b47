"""Open3D's reconstruction-system layout (``data.format: redwood``): what Open3D users
and the Redwood datasets already have.

Layout::

    ROOT/image/*.jpg|png   colour (also accepted: color/ or rgb/, as Open3D's recorder
                           and other tools name it)
    ROOT/depth/*.png       16-bit depth registered to colour, metres = value / 1000
                           (Open3D's default depth_scale; data.depth_scale overrides)
    ROOT/*.log             optional: the trajectory in Open3D's .log format
    ROOT/camera_intrinsic.json   optional: the camera (else Open3D's default PrimeSense)

Colour and depth are paired in sorted-name order, as Open3D's own reader does, and
must be equally many; timestamps are the positions 0, 1, 2, ...

The ``.log`` trajectory (Open3D ``read_pinhole_camera_trajectory``): per frame a line
of three integers (metadata) and four rows of the 4x4 camera-to-world matrix (OpenCV
camera axes, metres), one block per frame in frame order. A folder with several
``.log`` files is refused (the error lists them).

``camera_intrinsic.json`` is Open3D's ``PinholeCameraIntrinsic`` JSON: ``width``,
``height`` and ``intrinsic_matrix``, the 3x3 K in column-major order (fx, 0, 0, 0, fy,
0, cx, cy, 1). Without it the camera is Open3D's default
``PrimeSenseDefault``: 640x480, fx = fy = 525, cx = 319.5, cy = 239.5 (:data:`PRIMESENSE`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from eslam.config import DataConfig
from eslam.data.base import FileSequence, FrameReading, require_dir
from eslam.data.transform import transform_from_options
from eslam.errors import InputError
from eslam.io.pose_files import check_pose, text_lines
from eslam.types import Intrinsics

PRIMESENSE = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
"""Open3D's ``PinholeCameraIntrinsicParameters.PrimeSenseDefault``."""

INTRINSICS_JSON = "camera_intrinsic.json"
COLOUR_FOLDERS = ("image", "color", "rgb")
DEPTH_SCALE = 1000.0
"""Open3D's default depth_scale: depth PNG units per metre (millimetres)."""


def read_intrinsic_json(path: Path) -> Intrinsics:
    """The camera of an Open3D ``PinholeCameraIntrinsic`` JSON (column-major K)."""
    fix = 'expected {"width": W, "height": H, "intrinsic_matrix": [fx,0,0, 0,fy,0, cx,cy,1]}'
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        k = np.asarray(data["intrinsic_matrix"], dtype=np.float64).reshape(3, 3).T
        fx, fy, cx, cy = (float(v) for v in (k[0, 0], k[1, 1], k[0, 2], k[1, 2]))
        return Intrinsics(int(data["width"]), int(data["height"]), fx, fy, cx, cy)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(path, f"unreadable camera JSON ({error})", fix) from None
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(path, f"not an Open3D camera intrinsic ({error!r})", fix) from None


def read_log_trajectory(path: Path) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses of an Open3D ``.log`` trajectory, in file order.

    Raises:
        InputError: a block that is not 1 metadata line + 4 rows of 4 numbers, or a pose
            that is not rigid.
    """
    lines = text_lines(path)
    if len(lines) % 5:
        raise InputError(
            path,
            f"has {len(lines)} lines, not blocks of 5 (metadata + 4 matrix rows)",
            "write Open3D's .log format (write_pinhole_camera_trajectory)",
        )
    poses = []
    for start in range(0, len(lines), 5):
        number = lines[start][0]
        rows = []
        for row_number, text in lines[start + 1 : start + 5]:
            try:
                row = [float(v) for v in text.split()]
            except ValueError:
                row = []
            if len(row) != 4:
                raise InputError(path, f"line {row_number}: expected 4 numbers of a pose row")
            rows.append(row)
        poses.append(check_pose(np.array(rows), path, f"pose at line {number}"))
    return np.array(poses, dtype=np.float64).reshape(-1, 4, 4)


def _images(folder: Path, suffixes: tuple[str, ...]) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in suffixes)


class RedwoodSequence(FileSequence):
    """Reader of Open3D's reconstruction-system folder (see the module docstring).

    Args:
        root: the folder holding image/ (or color/, rgb/), depth/ and optionally a
            .log trajectory and camera_intrinsic.json.
        options: the ``data`` config section; depth_scale (default 1000), resize and
            crop apply.

    Raises:
        InputError: missing folders, unequal image counts, several .log files, a .log
            whose pose count is not the frame count, or a bad camera JSON.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = require_dir(Path(root), "image/ and depth/ (Open3D's layout)")
        colour_dirs = [self.root / n for n in COLOUR_FOLDERS if (self.root / n).is_dir()]
        if not colour_dirs:
            raise InputError(
                self.root, f"has no colour folder ({', '.join(COLOUR_FOLDERS)})", "check --data"
            )
        depth_dir = require_dir(self.root / "depth", "16-bit depth .png images")
        self._colour_paths = _images(colour_dirs[0], (".jpg", ".jpeg", ".png"))
        self._depth_paths = _images(depth_dir, (".png",))
        if len(self._colour_paths) != len(self._depth_paths) or not self._colour_paths:
            raise InputError(
                self.root,
                f"{colour_dirs[0].name}/ holds {len(self._colour_paths)} images and depth/ "
                f"{len(self._depth_paths)}",
                "colour and depth are paired in name order: keep them equally many",
            )
        camera_file = self.root / INTRINSICS_JSON
        camera = read_intrinsic_json(camera_file) if camera_file.is_file() else PRIMESENSE
        self.depth_scale = options.depth_scale or DEPTH_SCALE
        self.reading = FrameReading(
            camera, self.depth_scale, transform_from_options(options.resize, options.crop)
        )
        self.intrinsics = self.reading.intrinsics
        self._times = np.arange(len(self._colour_paths), dtype=np.float64)
        logs = sorted(self.root.glob("*.log"))
        if len(logs) > 1:
            raise InputError(
                self.root,
                f"holds several trajectories: {', '.join(p.name for p in logs)}",
                "keep the one of this sequence",
            )
        self._poses = None
        if logs:
            poses = read_log_trajectory(logs[0])
            if len(poses) != len(self._colour_paths):
                raise InputError(
                    logs[0],
                    f"has {len(poses)} poses for {len(self._colour_paths)} frames",
                    "one pose per frame, in frame order",
                )
            self._poses = poses
