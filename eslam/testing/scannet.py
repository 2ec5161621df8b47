"""Write frames in the ScanNet export layout (tests of the ScanNet reader)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
from PIL import Image

from eslam.atomic import write_text, write_with
from eslam.data.scannet import SCANNET_DEPTH_SCALE
from eslam.types import Frame, Intrinsics


def _matrix_text(matrix: np.ndarray) -> str:
    return "\n".join(" ".join(f"{value:.17g}" for value in row) for row in matrix) + "\n"


def write_scannet_sequence(
    root: str | Path,
    frames: Iterable[Frame],
    colour_size: tuple[int, int] | None = None,
    jpeg_quality: int = 95,
) -> int:
    """Write frames in the ScanNet export layout (atomically, file by file).

    A frame without ``pose_gt`` gets a ``-inf`` pose file, as ScanNet writes where its
    tracking was lost. Depth is written in millimetres; the frames' intrinsics become
    ``intrinsic_depth.txt`` and, scaled to ``colour_size``, ``intrinsic_color.txt``.

    Args:
        root: output folder (created).
        frames: frames sharing one camera.
        colour_size: (width, height) the colour images are resized to (ScanNet's colour
            camera has more pixels than its depth camera); None keeps the frame size.
        jpeg_quality: JPEG quality of the colour images.

    Returns:
        The number of frames written.
    """
    root = Path(root)
    intrinsics: Intrinsics | None = None
    count = 0
    for number, frame in enumerate(frames):
        if intrinsics is None:
            intrinsics = frame.intrinsics
        elif frame.intrinsics != intrinsics:
            raise ValueError("all frames of a ScanNet sequence must share one camera")
        rgb = Image.fromarray(frame.rgb)
        if colour_size is not None:
            rgb = rgb.resize(colour_size, Image.Resampling.BILINEAR)
        write_with(
            root / "color" / f"{number}.jpg",
            lambda tmp, image=rgb: image.save(tmp, format="JPEG", quality=jpeg_quality),
        )
        units = np.round(np.nan_to_num(frame.depth, nan=0.0) * SCANNET_DEPTH_SCALE)
        depth = Image.fromarray(np.clip(units, 0, 65535).astype(np.uint16))
        write_with(
            root / "depth" / f"{number}.png", lambda tmp, image=depth: image.save(tmp, "PNG")
        )
        pose = frame.pose_gt if frame.pose_gt is not None else np.full((4, 4), -np.inf)
        write_text(root / "pose" / f"{number}.txt", _matrix_text(pose))
        count += 1
    if intrinsics is None:
        raise ValueError("no frames to write")
    k_depth = np.eye(4)
    k_depth[:3, :3] = intrinsics.matrix()
    k_colour = np.eye(4)
    k_colour[:3, :3] = intrinsics.scaled(*(colour_size or intrinsics.size)).matrix()
    write_text(root / "intrinsic" / "intrinsic_depth.txt", _matrix_text(k_depth))
    write_text(root / "intrinsic" / "intrinsic_color.txt", _matrix_text(k_colour))
    return count
