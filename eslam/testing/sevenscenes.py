"""Write frames in the 7-Scenes layout (tests of the 7-Scenes reader)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
from PIL import Image

from eslam.atomic import write_text, write_with
from eslam.data.sevenscenes import INTRINSICS_FILE, SEVENSCENES_DEPTH_SCALE
from eslam.types import Frame, Intrinsics


def write_sevenscenes_sequence(
    root: str | Path, frames: Iterable[Frame], jpeg_quality: int = 95
) -> int:
    """Write frames in the 7-Scenes layout (atomically, file by file).

    Colour is JPEG (as in shared/data's redkitchen), depth millimetres, poses 4x4 text,
    and the frames' intrinsics go to ``camera-intrinsics.txt``.

    Returns:
        The number of frames written.
    """
    root = Path(root)
    intrinsics: Intrinsics | None = None
    count = 0
    for number, frame in enumerate(frames):
        if frame.pose_gt is None:
            raise ValueError(f"frame {frame.index} has no pose: 7-Scenes needs one per frame")
        if intrinsics is None:
            intrinsics = frame.intrinsics
        elif frame.intrinsics != intrinsics:
            raise ValueError("all frames of a 7-Scenes sequence must share one camera")
        stem = f"frame-{number:06d}"
        rgb = Image.fromarray(frame.rgb)
        write_with(
            root / f"{stem}.color.jpg",
            lambda tmp, image=rgb: image.save(tmp, format="JPEG", quality=jpeg_quality),
        )
        units = np.round(np.nan_to_num(frame.depth, nan=0.0) * SEVENSCENES_DEPTH_SCALE)
        depth = Image.fromarray(np.clip(units, 0, 65534).astype(np.uint16))
        write_with(
            root / f"{stem}.depth.png",
            lambda tmp, image=depth: image.save(tmp, "PNG"),
        )
        pose_text = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in frame.pose_gt)
        write_text(root / f"{stem}.pose.txt", pose_text + "\n")
        count += 1
    if intrinsics is None:
        raise ValueError("no frames to write")
    k_text = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in intrinsics.matrix())
    write_text(root / INTRINSICS_FILE, k_text + "\n")
    return count
