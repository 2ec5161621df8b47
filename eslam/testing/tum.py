"""Write frames in the TUM RGB-D layout (tests of the TUM reader and of runs on it).

The layout is :mod:`eslam.data.tum`'s: rgb.txt, depth.txt, groundtruth.txt and the
images, with TUM-like time stamps and ground truth at three times the frame rate.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from eslam.atomic import write_text, write_with
from eslam.data.tum import TUM_CAMERAS, TUM_DEPTH_SCALE
from eslam.data.undistort import distort_map, remap_bilinear, remap_nearest
from eslam.geometry.pose import interpolate_pose, quaternion_translation_from_pose
from eslam.types import Frame

TUM_EPOCH = 1305031452.0
"""First colour timestamp the writer uses (a TUM-like Unix time, seconds)."""
DEPTH_DELAY = 0.01
"""The writer stamps each depth image this many seconds after its colour image."""
GROUNDTRUTH_PER_FRAME = 3
"""The writer's ground-truth samples per frame interval (90 Hz at 30 Hz images): one at
the colour time, the others interpolated (SE(3) geodesic) between frames."""


def _stamp(time: float) -> str:
    return f"{time:.6f}"


def _list_text(kind: str, times: Sequence[float], folder: str) -> str:
    lines = [
        f"# {kind} images",
        "# written by eslam.testing.write_tum_sequence",
        "# timestamp filename",
    ]
    lines += [f"{_stamp(t)} {folder}/{_stamp(t)}.png" for t in times]
    return "\n".join(lines) + "\n"


def _groundtruth_text(times: Sequence[float], poses: Sequence[np.ndarray]) -> str:
    samples_t: list[float] = []
    samples: list[torch.Tensor] = []
    tensors = [torch.from_numpy(np.asarray(p, dtype=np.float64)) for p in poses]
    for i, (time, pose) in enumerate(zip(times, tensors, strict=True)):
        samples_t.append(time)
        samples.append(pose)
        if i + 1 < len(tensors):
            for k in range(1, GROUNDTRUTH_PER_FRAME):
                s = k / GROUNDTRUTH_PER_FRAME
                samples_t.append(time + s * (times[i + 1] - time))
                samples.append(interpolate_pose(pose, tensors[i + 1], s))
    q, t = quaternion_translation_from_pose(torch.stack(samples))
    lines = ["# ground truth trajectory", "# timestamp tx ty tz qx qy qz qw"]
    for time, ti, qi in zip(samples_t, t.tolist(), q.tolist(), strict=True):
        lines.append(" ".join([_stamp(time), *(f"{v:.17g}" for v in (*ti, *qi))]))
    return "\n".join(lines) + "\n"


def write_tum_sequence(
    root: str | Path,
    frames: Iterable[Frame],
    camera: str = "fr1",
    with_groundtruth: bool = True,
    distort: bool = False,
) -> int:
    """Write frames in the TUM RGB-D layout (atomically, file by file; lists last).

    Colour time i is TUM_EPOCH + frame.timestamp; depth images are stamped DEPTH_DELAY
    later; groundtruth.txt holds GROUNDTRUTH_PER_FRAME samples per frame interval, the
    one nearest each colour time being that frame's exact pose.

    Args:
        root: output folder (created).
        frames: frames with the 640x480 intrinsics of ``camera`` (ideal pinhole images),
            and poses when ``with_groundtruth``.
        camera: fr1, fr2 or fr3.
        with_groundtruth: write groundtruth.txt.
        distort: pass the images through the camera's lens distortion (colour bilinear,
            depth nearest), so that a reader must undistort them.

    Returns:
        The number of frames written.
    """
    root = Path(root)
    tum_camera = TUM_CAMERAS[camera]
    coords = None
    if distort and tum_camera.distortion is not None:
        coords = distort_map(tum_camera.intrinsics, tum_camera.distortion)
    (root / "rgb").mkdir(parents=True, exist_ok=True)
    (root / "depth").mkdir(parents=True, exist_ok=True)
    times: list[float] = []
    poses: list[np.ndarray] = []
    for frame in frames:
        if frame.intrinsics != tum_camera.intrinsics:
            raise ValueError(
                f"frame {frame.index} has intrinsics {frame.intrinsics}, not those of "
                f"TUM {camera} {tum_camera.intrinsics}"
            )
        if with_groundtruth and frame.pose_gt is None:
            raise ValueError(f"frame {frame.index} has no pose for groundtruth.txt")
        time = TUM_EPOCH + frame.timestamp
        rgb, depth = frame.rgb, np.nan_to_num(frame.depth, nan=0.0)
        if coords is not None:
            rgb, depth = remap_bilinear(rgb, coords), remap_nearest(depth, coords)
        units = np.clip(np.round(depth * TUM_DEPTH_SCALE), 0, 65535).astype(np.uint16)
        for image, path in (
            (Image.fromarray(rgb), root / "rgb" / f"{_stamp(time)}.png"),
            (Image.fromarray(units), root / "depth" / f"{_stamp(time + DEPTH_DELAY)}.png"),
        ):
            write_with(path, lambda tmp, image=image: image.save(tmp, format="PNG"))
        times.append(time)
        if frame.pose_gt is not None:
            poses.append(frame.pose_gt)
    if not times:
        raise ValueError("no frames to write")
    write_text(root / "depth.txt", _list_text("depth", [t + DEPTH_DELAY for t in times], "depth"))
    if with_groundtruth:
        write_text(root / "groundtruth.txt", _groundtruth_text(times, poses))
    write_text(root / "rgb.txt", _list_text("color", times, "rgb"))
    return len(times)
