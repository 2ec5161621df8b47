"""Replica, in the layout NICE-SLAM and ESLAM render it (and our synthetic scenes use).

Layout::

    ROOT/results/frame000000.jpg   colour (any size; all frames alike)
    ROOT/results/depth000000.png   uint16 depth, metres = value / scale
    ROOT/traj.txt                  line i: 16 floats, row-major 4x4 camera-to-world of frame i
    ROOT/cam_params.json           {"camera": {"w", "h", "fx", "fy", "cx", "cy", "scale"}}

Replica poses are camera-to-world in OpenCV camera axes already (x right, y down,
z forward), so no axis conversion happens here. Frame ``i`` takes line ``i`` of
``traj.txt`` by its file number, so a folder that holds a subset of a sequence
(traj.txt longer than the frames present) reads correctly.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from PIL import Image

from eslam.atomic import write_text, write_with
from eslam.config import DataConfig
from eslam.data.base import FileSequence, FrameReading, require_dir, require_file
from eslam.data.transform import transform_from_options
from eslam.errors import InputError
from eslam.io.pose_files import MATRIX_COLUMNS, matrix_poses, read_pose_table
from eslam.types import Frame, Intrinsics

REPLICA_DEPTH_SCALE = 6553.5
"""Replica depth PNG units per metre (NICE-SLAM's renderings; docs/method.md section 9)."""

_FRAME_RE = re.compile(r"^frame(\d+)\.(?:jpg|jpeg|png)$", re.IGNORECASE)
_DEPTH_RE = re.compile(r"^depth(\d+)\.png$", re.IGNORECASE)


def read_cam_params(path: Path) -> tuple[Intrinsics, float]:
    """Read Replica's ``cam_params.json``: intrinsics and depth scale."""
    require_file(path, "Replica camera parameters")
    try:
        camera = json.loads(path.read_text(encoding="utf-8"))["camera"]
        intrinsics = Intrinsics(
            width=int(camera["w"]),
            height=int(camera["h"]),
            fx=float(camera["fx"]),
            fy=float(camera["fy"]),
            cx=float(camera["cx"]),
            cy=float(camera["cy"]),
        )
        scale = float(camera.get("scale", REPLICA_DEPTH_SCALE))
    except json.JSONDecodeError as error:
        raise InputError(path, f"not valid JSON ({error})") from None
    except (KeyError, TypeError) as error:
        raise InputError(
            path,
            f"missing camera field {error}",
            'expected {"camera": {"w","h","fx","fy","cx","cy","scale"}}',
        ) from None
    except ValueError as error:
        raise InputError(path, f"invalid camera parameters ({error})") from None
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(path, f"depth scale must be positive, got {scale}")
    return intrinsics, scale


def read_traj(path: Path) -> np.ndarray:
    """Read ``traj.txt``: (N, 4, 4) float64 camera-to-world poses, each checked rigid."""
    require_file(path, "Replica trajectory, one 4x4 camera-to-world pose per line")
    return matrix_poses(read_pose_table(path, (MATRIX_COLUMNS,)))


def _numbered_files(folder: Path, pattern: re.Pattern[str]) -> dict[int, Path]:
    files: dict[int, Path] = {}
    for path in folder.iterdir():
        match = pattern.match(path.name)
        if match:
            files[int(match.group(1))] = path
    return files


class ReplicaSequence(FileSequence):
    """Reader of a Replica-layout folder (see the module docstring).

    Args:
        root: the sequence folder (holding ``results/``, ``traj.txt``, ``cam_params.json``).
        options: the ``data`` config section; its depth_scale (default: cam_params.json's),
            resize and crop (default: none) apply.

    Raises:
        InputError: missing folder or files, colour/depth without a partner, more frames
            than poses, a non-rigid or non-finite pose, or bad camera parameters.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = require_dir(
            Path(root), "a Replica sequence: results/, traj.txt, cam_params.json"
        )
        results = require_dir(self.root / "results", "frame*.jpg and depth*.png images")
        self.raw_intrinsics, file_scale = read_cam_params(self.root / "cam_params.json")
        self.depth_scale = options.depth_scale or file_scale
        self.transform = transform_from_options(options.resize, options.crop)
        self.reading = FrameReading(self.raw_intrinsics, self.depth_scale, self.transform)
        self.intrinsics = self.reading.intrinsics
        colour = _numbered_files(results, _FRAME_RE)
        depth = _numbered_files(results, _DEPTH_RE)
        if not colour and not depth:
            raise InputError(results, "holds no frame*.jpg / depth*.png images")
        for number in sorted(set(colour) ^ set(depth)):
            lone, missing = (
                (colour[number], f"depth{number:06d}.png")
                if number in colour
                else (depth[number], f"frame{number:06d}.jpg")
            )
            raise InputError(
                lone,
                f"has no partner {missing}: {len(colour)} colour vs {len(depth)} depth images",
                "every frame needs both a colour and a depth image",
            )
        self.numbers = sorted(colour)
        self._times = np.array(self.numbers, dtype=np.float64)
        self._colour_paths = [colour[n] for n in self.numbers]
        self._depth_paths = [depth[n] for n in self.numbers]
        traj_path = self.root / "traj.txt"
        all_poses = read_traj(traj_path)
        if self.numbers[-1] >= len(all_poses):
            raise InputError(
                traj_path,
                f"has {len(all_poses)} poses but the images go up to frame {self.numbers[-1]} "
                f"({len(self.numbers)} frames)",
                "traj.txt needs one line per frame",
            )
        self._poses = all_poses[self.numbers]


def write_replica_sequence(
    root: str | Path,
    frames: Iterable[Frame],
    depth_scale: float = REPLICA_DEPTH_SCALE,
    jpeg_quality: int = 95,
) -> int:
    """Write frames in the Replica layout (atomically, file by file).

    ``traj.txt`` and ``cam_params.json`` are written last, so a folder interrupted
    mid-way fails to read instead of reading as a shorter sequence.

    Args:
        root: output folder (created).
        frames: frames with ground-truth poses, all with the same intrinsics.
        depth_scale: PNG units per metre; depth above 65535 / depth_scale is clipped to it.
        jpeg_quality: JPEG quality of the colour images.

    Returns:
        The number of frames written.
    """
    root = Path(root)
    results = root / "results"
    results.mkdir(parents=True, exist_ok=True)
    lines: list[str] = []
    intrinsics: Intrinsics | None = None
    for number, frame in enumerate(frames):
        if frame.pose_gt is None:
            raise ValueError(f"frame {frame.index} has no pose: Replica needs one per frame")
        if intrinsics is None:
            intrinsics = frame.intrinsics
        elif frame.intrinsics != intrinsics:
            raise ValueError("all frames of a Replica sequence must share one camera")
        rgb = Image.fromarray(frame.rgb)
        write_with(
            results / f"frame{number:06d}.jpg",
            lambda tmp, image=rgb: image.save(tmp, format="JPEG", quality=jpeg_quality),
        )
        units = np.round(np.nan_to_num(frame.depth, nan=0.0) * depth_scale)
        depth = Image.fromarray(np.clip(units, 0, 65535).astype(np.uint16))
        write_with(
            results / f"depth{number:06d}.png",
            lambda tmp, image=depth: image.save(tmp, format="PNG"),
        )
        lines.append(" ".join(f"{value:.17g}" for value in frame.pose_gt.reshape(-1)))
    if intrinsics is None:
        raise ValueError("no frames to write")
    camera = {
        "camera": {
            "w": intrinsics.width,
            "h": intrinsics.height,
            "fx": intrinsics.fx,
            "fy": intrinsics.fy,
            "cx": intrinsics.cx,
            "cy": intrinsics.cy,
            "scale": depth_scale,
        }
    }
    write_text(root / "traj.txt", "\n".join(lines) + "\n")
    write_text(root / "cam_params.json", json.dumps(camera, indent=4) + "\n")
    return len(lines)
