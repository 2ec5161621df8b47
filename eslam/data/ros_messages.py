"""ROS messages to arrays: images, camera info and poses (any ROS 1 or ROS 2 bag).

Pure functions on deserialised messages (``rosbags`` objects: attributes named as in
the message definitions). ROS 1 and ROS 2 differ only in the camera info's field names
(``K``/``D`` against ``k``/``d``), which both are read under.

Images follow REP 118 and sensor_msgs/image_encodings: depth ``16UC1`` / ``mono16`` is
millimetres, ``32FC1`` metres (NaN = no depth); rows are ``step`` bytes apart (padding
allowed) and multi-byte values big-endian when ``is_bigendian`` is set.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from eslam.data.undistort import PlumbBob
from eslam.errors import InputError
from eslam.geometry.pose import pose_from_quaternion_translation
from eslam.types import Intrinsics

COLOUR_ENCODINGS = {"rgb8": (3, (0, 1, 2)), "bgr8": (3, (2, 1, 0)), "rgba8": (4, (0, 1, 2)),
                    "bgra8": (4, (2, 1, 0)), "mono8": (1, (0, 0, 0))}  # fmt: skip
"""Colour encodings read: channels per pixel and where R, G, B are."""

DEPTH_ENCODINGS = {"16UC1": ("u2", 1000.0), "mono16": ("u2", 1000.0), "32FC1": ("f4", 1.0)}
"""Depth encodings read: value type and units per metre (REP 118: mm or m)."""

PLUMB_BOB_MODELS = ("plumb_bob", "rational_polynomial", "brown conrady")
"""Distortion models whose first five coefficients are OpenCV's k1, k2, p1, p2, k3."""


def _pixels(msg, where: str | Path, dtype: str, channels: int) -> np.ndarray:
    """(H, W, channels) view of an Image's data, honouring step and is_bigendian."""
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    item = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    row = width * channels * item.itemsize
    data = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    if step < row or data.size < step * (height - 1) + row:
        raise InputError(
            where,
            f"{msg.encoding} image {width}x{height} has step {step} and {data.size} bytes, "
            f"too few for its size",
            "the recording is damaged; re-record it",
        )
    rows = np.lib.stride_tricks.as_strided(data, (height, row), (step, 1))
    return np.ascontiguousarray(rows).view(item).reshape(height, width, channels)


def image_kind(encoding: str) -> str | None:
    """'colour', 'depth' or None (an encoding eslam does not read)."""
    if encoding in COLOUR_ENCODINGS:
        return "colour"
    if encoding in DEPTH_ENCODINGS:
        return "depth"
    return None


def colour_image(msg, where: str | Path) -> np.ndarray:
    """A sensor_msgs/Image in rgb8, bgr8, rgba8, bgra8 or mono8 as (H, W, 3) uint8 RGB.

    Raises:
        InputError: another encoding, or too little data for the image's size.
    """
    if msg.encoding not in COLOUR_ENCODINGS:
        raise InputError(
            where,
            f"colour image encoding '{msg.encoding}' is not read "
            f"(read: {', '.join(COLOUR_ENCODINGS)})",
            "record colour as rgb8 or bgr8, or set data.topics.colour",
        )
    channels, order = COLOUR_ENCODINGS[msg.encoding]
    return _pixels(msg, where, "u1", channels)[:, :, list(order)].copy()


def depth_image(msg, where: str | Path) -> tuple[np.ndarray, float]:
    """A sensor_msgs/Image depth as (H, W) float32 in its units, and units per metre.

    16UC1 / mono16: millimetres (1000 per metre); 32FC1: metres (1 per metre), NaN and
    infinities become 0 (no depth).

    Raises:
        InputError: another encoding, or too little data for the image's size.
    """
    if msg.encoding not in DEPTH_ENCODINGS:
        raise InputError(
            where,
            f"depth image encoding '{msg.encoding}' is not read "
            f"(read: {', '.join(DEPTH_ENCODINGS)})",
            "record depth as 16UC1 (mm) or 32FC1 (m), or set data.topics.depth",
        )
    dtype, per_metre = DEPTH_ENCODINGS[msg.encoding]
    values = _pixels(msg, where, dtype, 1)[:, :, 0].astype(np.float32)
    values[~np.isfinite(values)] = 0.0
    return values, per_metre


@dataclass(frozen=True)
class CameraModel:
    """A sensor_msgs/CameraInfo read: the pinhole camera and its lens distortion.

    Attributes:
        intrinsics: width, height and K.
        distortion: the plumb-bob coefficients, or None without distortion.
    """

    intrinsics: Intrinsics
    distortion: PlumbBob | None


def camera_model(msg, where: str | Path) -> CameraModel:
    """The camera of a CameraInfo (ROS 1 ``K``/``D`` or ROS 2 ``k``/``d``).

    Zero coefficients in any model mean no distortion; non-zero ones are read for
    plumb_bob and rational_polynomial (whose k4-k6 must be 0) and refused otherwise.

    Raises:
        InputError: a zero focal length or size, or distortion eslam cannot undo.
    """
    k = np.asarray(getattr(msg, "k", getattr(msg, "K", None)), dtype=np.float64).reshape(-1)
    d = np.asarray(getattr(msg, "d", getattr(msg, "D", ())), dtype=np.float64).reshape(-1)
    try:
        fx, fy, cx, cy = (float(k[i]) for i in (0, 4, 2, 5))
        intrinsics = Intrinsics(int(msg.width), int(msg.height), fx, fy, cx, cy)
    except (ValueError, IndexError) as error:
        raise InputError(
            where, f"camera info holds no usable camera ({error})", "check the camera_info topic"
        ) from None
    if not d.any():
        return CameraModel(intrinsics, None)
    model = str(msg.distortion_model).lower()
    if model not in PLUMB_BOB_MODELS or d[5:].any():
        raise InputError(
            where,
            f"distortion model '{msg.distortion_model}' with coefficients {d.tolist()} "
            "cannot be undone (eslam undistorts plumb_bob k1, k2, p1, p2, k3)",
            "record rectified images (image_rect topics) or undistort the bag first",
        )
    padded = np.zeros(5)
    padded[: min(5, d.size)] = d[:5]
    return CameraModel(intrinsics, PlumbBob(*padded.tolist()))


def stamp_ns(msg) -> int:
    """A message's header stamp in nanoseconds (ROS 1 ``secs``/``nsecs`` as rosbags reads
    them: ``sec``/``nanosec``)."""
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _pose(position, orientation) -> np.ndarray:
    q = torch.tensor(
        [orientation.x, orientation.y, orientation.z, orientation.w], dtype=torch.float64
    )
    t = torch.tensor([position.x, position.y, position.z], dtype=torch.float64)
    return pose_from_quaternion_translation(q, t).numpy()


POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
              "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage")  # fmt: skip
"""Message types a ground-truth pose topic may have."""


def message_poses(
    msg, msgtype: str, frames: tuple[str, str] | None
) -> list[tuple[int, np.ndarray]]:
    """(stamp ns, 4x4 camera-to-world) of a pose message; a TFMessage gives those of its
    transforms from ``frames[0]`` to ``frames[1]`` (all of them when ``frames`` is None)."""
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return [(stamp_ns(msg), _pose(msg.pose.position, msg.pose.orientation))]
    if msgtype in ("geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry"):
        pose = msg.pose.pose
        return [(stamp_ns(msg), _pose(pose.position, pose.orientation))]
    if msgtype == "tf2_msgs/msg/TFMessage":
        found = []
        for transform in msg.transforms:
            if frames is None or (transform.header.frame_id, transform.child_frame_id) == frames:
                moved = transform.transform
                found.append((stamp_ns(transform), _pose(moved.translation, moved.rotation)))
        return found
    raise ValueError(f"not a pose message type: {msgtype}")


def transform_frames(msg) -> set[tuple[str, str]]:
    """The (parent, child) frame ids of a TFMessage's transforms."""
    return {(t.header.frame_id, t.child_frame_id) for t in msg.transforms}
