"""Write frames in the plain folder layout (tests of the folder reader)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch
import yaml
from PIL import Image

from eslam.atomic import write_text, write_with
from eslam.data.folder import INTRINSICS_FILE, POSES_FILE
from eslam.geometry.pose import quaternion_translation_from_pose
from eslam.types import Frame, Intrinsics


def write_folder_sequence(
    root: str | Path,
    frames: Iterable[Frame],
    depth_scale: float = 1000.0,
    pose_format: str | None = "tum",
) -> int:
    """Write frames in the plain folder layout (atomically, file by file).

    Stems are the zero-padded frame positions (``000000``), colour and depth are PNG.

    Args:
        root: output folder (created).
        frames: frames sharing one camera.
        depth_scale: PNG units per metre, written to intrinsics.yaml.
        pose_format: "tum" (timestamped lines, timestamp = the stem's number), "matrix"
            (one 4x4 per line) or None (no poses.txt). Frames without a pose get no
            "tum" line; "matrix" needs every pose.

    Returns:
        The number of frames written.
    """
    if pose_format not in ("tum", "matrix", None):
        raise ValueError(f"pose_format must be 'tum', 'matrix' or None, got {pose_format!r}")
    root = Path(root)
    intrinsics: Intrinsics | None = None
    lines: list[str] = []
    count = 0
    for number, frame in enumerate(frames):
        if intrinsics is None:
            intrinsics = frame.intrinsics
        elif frame.intrinsics != intrinsics:
            raise ValueError("all frames of a folder sequence must share one camera")
        stem = f"{number:06d}"
        rgb = Image.fromarray(frame.rgb)
        write_with(root / "color" / f"{stem}.png", lambda tmp, image=rgb: image.save(tmp, "PNG"))
        units = np.round(np.nan_to_num(frame.depth, nan=0.0) * depth_scale)
        depth = Image.fromarray(np.clip(units, 0, 65535).astype(np.uint16))
        write_with(root / "depth" / f"{stem}.png", lambda tmp, image=depth: image.save(tmp, "PNG"))
        if pose_format == "matrix":
            if frame.pose_gt is None:
                raise ValueError(f"frame {frame.index} has no pose: 'matrix' needs one per frame")
            lines.append(" ".join(f"{v:.17g}" for v in frame.pose_gt.reshape(-1)))
        elif pose_format == "tum" and frame.pose_gt is not None:
            q, t = quaternion_translation_from_pose(torch.from_numpy(frame.pose_gt))
            values = [float(number), *t.tolist(), *q.tolist()]
            lines.append(" ".join(f"{v:.17g}" for v in values))
        count += 1
    if intrinsics is None:
        raise ValueError("no frames to write")
    camera = {
        "width": intrinsics.width,
        "height": intrinsics.height,
        "fx": intrinsics.fx,
        "fy": intrinsics.fy,
        "cx": intrinsics.cx,
        "cy": intrinsics.cy,
        "depth_scale": depth_scale,
    }
    write_text(root / INTRINSICS_FILE, yaml.safe_dump(camera, sort_keys=False))
    if pose_format is not None:
        header = "# timestamp tx ty tz qx qy qz qw\n" if pose_format == "tum" else ""
        write_text(root / POSES_FILE, header + "\n".join(lines) + "\n")
    return count
