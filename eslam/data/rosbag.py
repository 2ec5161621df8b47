"""Reader of ROS bags (``data.format: rosbag``): ROS 1 ``.bag``, ROS 2 bag folders and
their ``.db3`` / ``.mcap`` files, read with the pure-Python ``rosbags``.

Topics (``data.topics``; docs/live.md): colour and depth ``sensor_msgs/Image`` and the
colour camera's ``sensor_msgs/CameraInfo``. Unset, each is realsense-ros's default
(:data:`DEFAULT_TOPICS`) when the bag has it, else the bag's only topic of its kind
(an Image topic's kind is its first message's encoding); otherwise the error lists the
topics found. Depth must be registered to colour (same size and camera, as
realsense-ros's ``aligned_depth_to_color``); distortion in the camera info is undone
(plumb bob) or refused.

Opening indexes the bag once: every colour and depth message's header stamp. Repeated
stamps are dropped, and colour and depth are paired by header stamp (mutual nearest
within :data:`PAIR_TOLERANCE_S`), never by arrival order. Frames are then decoded one
at a time, each read by its time in the bag. Timestamps are the colour header stamps in
seconds. An optional pose topic (``data.topics.pose``: PoseStamped, Odometry or TF)
gives ground truth: the pose nearest each frame's stamp within
:data:`POSE_TOLERANCE_S`, NaN for frames with none.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.config import DataConfig
from eslam.data.bags import open_bag
from eslam.data.base import FrameReading
from eslam.data.ros_messages import (
    DEPTH_ENCODINGS,
    POSE_TYPES,
    camera_model,
    colour_image,
    depth_image,
    image_kind,
    message_poses,
    stamp_ns,
    transform_frames,
)
from eslam.data.transform import transform_from_options
from eslam.data.undistort import Undistorter
from eslam.errors import InputError
from eslam.types import Frame

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"

DEFAULT_TOPICS = {
    "colour": "/camera/color/image_raw",
    "depth": "/camera/aligned_depth_to_color/image_raw",
    "camera_info": "/camera/color/camera_info",
}
"""realsense-ros's topics of colour, depth aligned to colour, and the colour camera."""

PAIR_TOLERANCE_S = 0.02
"""Largest header-stamp difference of a colour and a depth image paired into one frame,
seconds (TUM RGB-D's association uses the same 20 ms); realsense-ros stamps aligned
depth with its colour image's stamp exactly."""

POSE_TOLERANCE_S = 0.02
"""Largest difference between a frame's stamp and the ground-truth pose given to it, s."""


@dataclass(frozen=True)
class MessageRef:
    """Where one image message is: its header stamp and its time in the bag (ns)."""

    stamp: int
    logged: int


def pair_by_stamp(colour: np.ndarray, depth: np.ndarray, tolerance: int) -> list[tuple[int, int]]:
    """Pairs (i, j) of colour stamp i and depth stamp j that are each other's nearest and
    at most ``tolerance`` apart, in colour order.

    Args:
        colour: (N,) sorted int64 stamps.
        depth: (M,) sorted int64 stamps.
        tolerance: largest |colour - depth|, same units.
    """

    def nearest(stamps: np.ndarray, value: int) -> int:
        right = int(np.searchsorted(stamps, value))
        options = [k for k in (right - 1, right) if 0 <= k < len(stamps)]
        return min(options, key=lambda k: (abs(int(stamps[k]) - value), k))

    pairs = []
    if len(colour) == 0 or len(depth) == 0:
        return pairs
    for i, stamp in enumerate(colour):
        j = nearest(depth, int(stamp))
        if abs(int(depth[j]) - int(stamp)) <= tolerance and nearest(colour, int(depth[j])) == i:
            pairs.append((i, j))
    return pairs


def _topic_list(topics: dict[str, str], kinds: dict[str, str]) -> str:
    shown = []
    for name, msgtype in sorted(topics.items()):
        short = msgtype.replace("/msg/", "/")
        kind = kinds.get(name)
        shown.append(f"{name} ({short}{', ' + kind if kind else ''})")
    return "; ".join(shown) or "none"


class RosbagSequence:
    """Frames of a ROS bag (module doc).

    Args:
        root: the bag: a .bag, .db3 or .mcap file or a ROS 2 bag folder.
        options: the ``data`` config section: topics, depth_scale (default: 1000 for
            16-bit depth, 1 for 32FC1), resize and crop apply.

    Raises:
        InputError: not a bag, topics missing or ambiguous (the message lists the bag's
            topics), unreadable encodings, depth not registered to colour, no frame
            pairs, or a pose topic without usable poses.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = Path(root)
        self._reader = open_bag(self.root)
        try:
            self._open(options)
        except BaseException:
            self.close()
            raise

    def _open(self, options: DataConfig) -> None:
        reader = self._reader
        topics = {name: str(info.msgtype) for name, info in reader.topics.items()}
        self._connections = {name: list(info.connections) for name, info in reader.topics.items()}
        kinds = {name: self._image_kind(name) for name, kind in topics.items() if kind == IMAGE}
        wanted = options.topics
        listing = _topic_list(topics, {k: str(v) for k, v in kinds.items() if v})
        self.topics = {
            "colour": self._choose("colour", wanted.colour, topics, kinds, listing),
            "depth": self._choose("depth", wanted.depth, topics, kinds, listing),
            "camera_info": self._choose("camera_info", wanted.camera_info, topics, kinds, listing),
        }
        colour, colour_size, _ = self._index(self.topics["colour"])
        depth, depth_size, encodings = self._index(self.topics["depth"])
        if colour_size != depth_size:
            raise InputError(
                self.root,
                f"depth on {self.topics['depth']} is {depth_size[0]}x{depth_size[1]} but colour "
                f"on {self.topics['colour']} is {colour_size[0]}x{colour_size[1]}: depth must be "
                "registered to colour",
                "record depth aligned to colour (realsense-ros align_depth.enable:=true)",
            )
        pairs = pair_by_stamp(
            np.array([m.stamp for m in colour], dtype=np.int64),
            np.array([m.stamp for m in depth], dtype=np.int64),
            round(PAIR_TOLERANCE_S * 1e9),
        )
        if not pairs:
            raise InputError(
                self.root,
                f"no colour image on {self.topics['colour']} has a depth image on "
                f"{self.topics['depth']} within {PAIR_TOLERANCE_S * 1000:g} ms of its stamp",
                "colour and depth are paired by header stamp; check the topics",
            )
        self._frames = [(colour[i], depth[j]) for i, j in pairs]
        self._times = np.array([c.stamp for c, _ in self._frames], dtype=np.float64) / 1e9
        camera = camera_model(self._first(self.topics["camera_info"]), self._where("camera_info"))
        self.depth_scale = options.depth_scale or DEPTH_ENCODINGS[encodings][1]
        prepare = None
        if camera.distortion is not None:
            prepare = Undistorter(camera.intrinsics, camera.distortion).images
        self.raw_intrinsics = camera.intrinsics
        self.reading = FrameReading(
            camera.intrinsics,
            self.depth_scale,
            transform_from_options(options.resize, options.crop),
            prepare=prepare,
        )
        self.intrinsics = self.reading.intrinsics
        self._poses = None
        if wanted.pose is not None:
            self._poses = self._read_poses(wanted.pose, wanted.pose_frames, topics, listing)

    def _where(self, role: str, stamp: int | None = None) -> str:
        at = "" if stamp is None else f" at {stamp / 1e9:.6f} s"
        return f"{self.root} [{self.topics[role]}{at}]"

    def _image_kind(self, topic: str) -> str | None:
        """'colour' or 'depth' by the topic's first encoding; None when empty or unread."""
        message = self._first(topic, required=False)
        return image_kind(str(message.encoding)) if message is not None else None

    def _first(self, topic: str, required: bool = True):
        for connection, _, raw in self._reader.messages(connections=self._connections[topic]):
            return self._reader.deserialize(raw, connection.msgtype)
        if required:
            raise InputError(self.root, f"topic {topic} holds no message", "check data.topics")
        return None

    def _choose(
        self,
        role: str,
        wanted: str | None,
        topics: dict[str, str],
        kinds: dict[str, str | None],
        listing: str,
    ) -> str:
        if role == "camera_info":
            candidates = [name for name, kind in topics.items() if kind == CAMERA_INFO]
            what = "sensor_msgs/CameraInfo"
        else:
            candidates = [name for name, kind in kinds.items() if kind == role]
            what = f"{role} sensor_msgs/Image"
        if wanted is not None:
            if wanted not in topics:
                raise InputError(
                    self.root,
                    f"has no topic {wanted} (data.topics.{role}); its topics: {listing}",
                    f"set data.topics.{role} to one of them",
                )
            if wanted not in candidates:
                raise InputError(
                    self.root,
                    f"topic {wanted} (data.topics.{role}) is no {what}; its topics: {listing}",
                    f"set data.topics.{role} to a {what} topic",
                )
            return wanted
        if DEFAULT_TOPICS[role] in candidates:
            return DEFAULT_TOPICS[role]
        if len(candidates) == 1:
            return candidates[0]
        found = "no" if not candidates else f"{len(candidates)}"
        raise InputError(
            self.root,
            f"{found} {what} topics and no {DEFAULT_TOPICS[role]}; its topics: {listing}",
            f"set data.topics.{role}=TOPIC",
        )

    def _index(self, topic: str) -> tuple[list[MessageRef], tuple[int, int], str]:
        """The topic's messages in stamp order (repeated stamps dropped), their image size
        and encoding (one per topic)."""
        refs: dict[int, MessageRef] = {}
        sizes: set[tuple[int, int]] = set()
        encodings: set[str] = set()
        for connection, logged, raw in self._reader.messages(connections=self._connections[topic]):
            message = self._reader.deserialize(raw, connection.msgtype)
            refs.setdefault(stamp_ns(message), MessageRef(stamp_ns(message), logged))
            sizes.add((int(message.width), int(message.height)))
            encodings.add(str(message.encoding))
        if len(sizes) > 1 or len(encodings) > 1:
            raise InputError(
                self.root,
                f"topic {topic} mixes image sizes {sorted(sizes)} or encodings {sorted(encodings)}",
                "record one stream per topic",
            )
        return [refs[s] for s in sorted(refs)], sizes.pop(), encodings.pop()

    def _message(self, role: str, ref: MessageRef):
        for connection, _, raw in self._reader.messages(
            connections=self._connections[self.topics[role]], start=ref.logged, stop=ref.logged + 1
        ):
            message = self._reader.deserialize(raw, connection.msgtype)
            if stamp_ns(message) == ref.stamp:
                return message
        raise InputError(self._where(role, ref.stamp), "message not found again", "re-open the bag")

    def _read_poses(
        self,
        topic: str,
        frames: tuple[str, str] | None,
        topics: dict[str, str],
        listing: str,
    ) -> np.ndarray:
        msgtype = topics.get(topic)
        if msgtype not in POSE_TYPES:
            found = "no such topic" if msgtype is None else f"type {msgtype}"
            raise InputError(
                self.root,
                f"pose topic {topic} (data.topics.pose) has {found}; its topics: {listing}",
                "name a PoseStamped, Odometry or TFMessage topic of the camera's optical frame",
            )
        messages = [
            self._reader.deserialize(raw, connection.msgtype)
            for connection, _, raw in self._reader.messages(connections=self._connections[topic])
        ]
        if msgtype == "tf2_msgs/msg/TFMessage" and frames is None:
            pairs = set().union(*(transform_frames(m) for m in messages))
            if len(pairs) != 1:
                shown = ", ".join(f"[{a}, {b}]" for a, b in sorted(pairs)) or "none"
                raise InputError(
                    self.root,
                    f"TF topic {topic} holds transforms {shown}",
                    "set data.topics.pose_frames=[PARENT, CHILD] to the camera's",
                )
            frames = pairs.pop()
        found = sorted(
            (stamp, pose)
            for m in messages
            for stamp, pose in message_poses(m, msgtype, None if frames is None else tuple(frames))
        )
        stamps = [stamp for stamp, _ in found]
        poses = np.full((len(self._frames), 4, 4), np.nan)
        tolerance = round(POSE_TOLERANCE_S * 1e9)
        for index, (colour, _) in enumerate(self._frames):
            right = bisect.bisect_left(stamps, colour.stamp)
            near = [k for k in (right - 1, right) if 0 <= k < len(stamps)]
            if near:
                best = min(near, key=lambda k: abs(stamps[k] - colour.stamp))
                if abs(stamps[best] - colour.stamp) <= tolerance:
                    poses[index] = found[best][1]
        if np.isnan(poses).all():
            raise InputError(
                self.root,
                f"no pose on {topic} lies within {POSE_TOLERANCE_S * 1000:g} ms of a frame",
                "check data.topics.pose (and pose_frames) and the recording's clocks",
            )
        return poses

    def __len__(self) -> int:
        return len(self._frames)

    def __getitem__(self, index: int) -> Frame:
        if not 0 <= index < len(self):
            raise IndexError(f"frame {index} out of range for {len(self)} frames")
        colour_ref, depth_ref = self._frames[index]
        colour_where = self._where("colour", colour_ref.stamp)
        depth_where = self._where("depth", depth_ref.stamp)
        rgb = colour_image(self._message("colour", colour_ref), colour_where)
        units, _ = depth_image(self._message("depth", depth_ref), depth_where)
        pose = None if self._poses is None else self._poses[index]
        return self.reading.build(
            index, (rgb, units), pose, self._times[index], (colour_where, depth_where)
        )

    def gt_poses(self) -> np.ndarray | None:
        """(N, 4, 4) poses from the pose topic (NaN where none is near), or None."""
        return None if self._poses is None else self._poses.copy()

    def timestamps(self) -> np.ndarray:
        """(N,) colour header stamps, seconds."""
        return self._times.copy()

    def frame_files(self, index: int) -> tuple[Path, Path]:
        """The recording holds every frame: (bag, bag), for the input fingerprint."""
        return self.root, self.root

    def close(self) -> None:
        """Close the bag (the sequence cannot read frames afterwards)."""
        if self._reader is not None and self._reader.stack is not None:
            self._reader.close()
