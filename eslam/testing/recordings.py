"""Write recordings of frames: ROS bags (rosbags) and RealSense recordings (the SDK's
software device), for tests and the examples in docs/live.md.

Both write what the readers of :mod:`eslam.data.rosbag` and :mod:`eslam.data.realsense`
expect from real sensors: realsense-ros's topics and encodings, librealsense's own
recorder layout.

Over 400 lines on purpose: the two writers encode the same sensor conventions the two
readers expect, side by side so a change to one shows in the other.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from eslam.data.rosbag import DEFAULT_TOPICS
from eslam.geometry.pose import quaternion_translation_from_pose
from eslam.types import Frame, Intrinsics

BAG_STORAGES = ("ros1", "sqlite3", "mcap")
"""What :func:`write_ros_bag` writes: a ROS 1 .bag, or a ROS 2 bag folder in sqlite3 or mcap."""

START_NS = 1_700_000_000_000_000_000
"""Header stamp of the first frame written (a plausible wall-clock time), ns."""

FRAME_PERIOD_NS = 33_333_333
"""Stamp step between frames (30 Hz), ns."""


@dataclass(frozen=True)
class BagLayout:
    """How :func:`write_ros_bag` writes frames.

    Attributes:
        storage: one of :data:`BAG_STORAGES`.
        colour_encoding: rgb8, bgr8, rgba8 or bgra8.
        depth_encoding: 16UC1 or mono16 (millimetres) or 32FC1 (metres, NaN = none).
        topics: colour, depth and camera_info topic names.
        pose_topic: a topic for the ground-truth poses, or None.
        pose_type: PoseStamped, Odometry or TFMessage (parent "world", child "camera").
        row_padding: bytes added at the end of every image row (step > width * bytes).
        big_endian: write 16-bit depth big-endian (is_bigendian = 1).
        distortion: plumb-bob coefficients written to the camera info.
        depth_offset_ns: added to every depth stamp (colour and depth not simultaneous).
        extra_colour_topics: more topics carrying the same colour images.
    """

    storage: str = "ros1"
    colour_encoding: str = "rgb8"
    depth_encoding: str = "16UC1"
    topics: tuple[str, str, str] = (
        DEFAULT_TOPICS["colour"],
        DEFAULT_TOPICS["depth"],
        DEFAULT_TOPICS["camera_info"],
    )
    pose_topic: str | None = None
    pose_type: str = "PoseStamped"
    row_padding: int = 0
    big_endian: bool = False
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    depth_offset_ns: int = 0
    extra_colour_topics: tuple[str, ...] = ()


def frame_stamp_ns(number: int) -> int:
    """Header stamp :func:`write_ros_bag` gives frame ``number``, ns."""
    return START_NS + number * FRAME_PERIOD_NS


def depth_millimetres(depth: np.ndarray) -> np.ndarray:
    """(H, W) metres -> uint16 millimetres as 16UC1 stores them (0 = none)."""
    return np.clip(np.round(np.nan_to_num(depth) * 1000.0), 0, 65535).astype(np.uint16)


def _typestore(storage: str):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if storage == "ros1" else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.fielddefs:
        store.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    return store


class _Messages:
    """Builds the messages of one bag's message types (ROS 1 or ROS 2 field names)."""

    def __init__(self, store, ros1: bool) -> None:
        self.store = store
        self.ros1 = ros1
        self.types = store.types

    def header(self, stamp: int, frame_id: str, seq: int = 0):
        time = self.types["builtin_interfaces/msg/Time"](
            sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000
        )
        if self.ros1:
            return self.types["std_msgs/msg/Header"](seq=seq, stamp=time, frame_id=frame_id)
        return self.types["std_msgs/msg/Header"](stamp=time, frame_id=frame_id)

    def image(self, header, pixels: np.ndarray, encoding: str, padding: int, big: bool):
        height, width = pixels.shape[:2]
        rows = pixels.reshape(height, -1).view(np.uint8)
        rows = np.concatenate([rows, np.zeros((height, padding), np.uint8)], axis=1)
        return self.types["sensor_msgs/msg/Image"](
            header=header,
            height=height,
            width=width,
            encoding=encoding,
            is_bigendian=int(big),
            step=rows.shape[1],
            data=np.ascontiguousarray(rows).reshape(-1),
        )

    def camera_info(self, header, camera: Intrinsics, distortion: Sequence[float]):
        k = np.array([camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1], np.float64)
        p = np.array([camera.fx, 0, camera.cx, 0, 0, camera.fy, camera.cy, 0, 0, 0, 1, 0.0])
        fields = {"D": np.array(distortion, np.float64), "K": k, "R": np.eye(3).reshape(-1), "P": p}
        if not self.ros1:
            fields = {name.lower(): value for name, value in fields.items()}
        roi = self.types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        return self.types["sensor_msgs/msg/CameraInfo"](
            header=header,
            height=camera.height,
            width=camera.width,
            distortion_model="plumb_bob",
            binning_x=0,
            binning_y=0,
            roi=roi,
            **fields,
        )

    def pose(self, header, pose: np.ndarray, kind: str):
        q, t = quaternion_translation_from_pose(torch.from_numpy(pose))
        point = self.types["geometry_msgs/msg/Point"](*t.tolist())
        rotation = self.types["geometry_msgs/msg/Quaternion"](*q.tolist())
        if kind == "PoseStamped":
            return self.types["geometry_msgs/msg/PoseStamped"](
                header=header, pose=self.types["geometry_msgs/msg/Pose"](point, rotation)
            )
        if kind == "Odometry":
            covariance = np.zeros(36)
            pose_msg = self.types["geometry_msgs/msg/PoseWithCovariance"](
                self.types["geometry_msgs/msg/Pose"](point, rotation), covariance
            )
            zero = self.types["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0)
            twist = self.types["geometry_msgs/msg/TwistWithCovariance"](
                self.types["geometry_msgs/msg/Twist"](zero, zero), covariance
            )
            return self.types["nav_msgs/msg/Odometry"](header, "camera", pose_msg, twist)
        if kind == "TFMessage":
            shift = self.types["geometry_msgs/msg/Vector3"](*t.tolist())
            transform = self.types["geometry_msgs/msg/TransformStamped"](
                header, "camera", self.types["geometry_msgs/msg/Transform"](shift, rotation)
            )
            other = self.types["geometry_msgs/msg/TransformStamped"](
                self.header(0, "map"), "world", self.types["geometry_msgs/msg/Transform"](
                    self.types["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0),
                    self.types["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
                ),
            )  # fmt: skip
            other.header.stamp = header.stamp
            return self.types["tf2_msgs/msg/TFMessage"]([transform, other])
        raise ValueError(f"pose_type must be PoseStamped, Odometry or TFMessage, got {kind!r}")


_POSE_TYPES = {
    "PoseStamped": "geometry_msgs/msg/PoseStamped",
    "Odometry": "nav_msgs/msg/Odometry",
    "TFMessage": "tf2_msgs/msg/TFMessage",
}


def _colour_pixels(rgb: np.ndarray, encoding: str) -> np.ndarray:
    order = {"rgb8": [0, 1, 2], "bgr8": [2, 1, 0], "rgba8": [0, 1, 2], "bgra8": [2, 1, 0]}
    if encoding not in order:
        raise ValueError(f"colour_encoding must be one of {sorted(order)}, got {encoding!r}")
    pixels = rgb[:, :, order[encoding]]
    if encoding.endswith("a8"):
        pixels = np.concatenate([pixels, np.full((*rgb.shape[:2], 1), 255, np.uint8)], axis=2)
    return np.ascontiguousarray(pixels)


def _depth_pixels(depth: np.ndarray, encoding: str, big: bool) -> np.ndarray:
    if encoding in ("16UC1", "mono16"):
        values = depth_millimetres(depth)
        return values.astype(">u2") if big else values
    if encoding == "32FC1":
        metres = depth.astype(np.float32).copy()
        metres[~(metres > 0)] = np.nan
        return metres.astype(">f4") if big else metres
    raise ValueError(f"depth_encoding must be 16UC1, mono16 or 32FC1, got {encoding!r}")


def write_ros_bag(
    path: str | Path, frames: Sequence[Frame], layout: BagLayout = BagLayout()
) -> Path:
    """Write ``frames`` as a ROS bag: per frame a colour and a depth Image, a CameraInfo
    and (``layout.pose_topic``) the ground-truth pose, stamped :func:`frame_stamp_ns`.

    Depth goes in first, colour last, so arrival order differs from stamp pairing.

    Args:
        path: a .bag file (storage ros1) or a folder to create (sqlite3, mcap).
        frames: frames sharing one camera.
        layout: encodings, topics and storage.

    Returns:
        ``path``.
    """
    if layout.storage not in BAG_STORAGES:
        raise ValueError(f"storage must be one of {BAG_STORAGES}, got {layout.storage!r}")
    path = Path(path)
    ros1 = layout.storage == "ros1"
    store = _typestore(layout.storage)
    build = _Messages(store, ros1)
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
        serialize = store.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if layout.storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer(path, version=9, storage_plugin=plugin)
        serialize = store.serialize_cdr
    colour_topic, depth_topic, info_topic = layout.topics
    big = layout.big_endian
    with writer:
        image_type = "sensor_msgs/msg/Image"
        connections = {
            "depth": writer.add_connection(depth_topic, image_type, typestore=store),
            "colour": writer.add_connection(colour_topic, image_type, typestore=store),
            "info": writer.add_connection(
                info_topic, "sensor_msgs/msg/CameraInfo", typestore=store
            ),
        }
        for number, topic in enumerate(layout.extra_colour_topics):
            connections[f"extra{number}"] = writer.add_connection(
                topic, image_type, typestore=store
            )
        if layout.pose_topic is not None:
            pose_type = _POSE_TYPES[layout.pose_type]
            connections["pose"] = writer.add_connection(
                layout.pose_topic, pose_type, typestore=store
            )
        for number, frame in enumerate(frames):
            stamp = frame_stamp_ns(number)
            header = build.header(stamp, "camera_color_optical_frame", number)
            depth_header = build.header(
                stamp + layout.depth_offset_ns, "camera_color_optical_frame", number
            )
            depth_pixels = _depth_pixels(frame.depth, layout.depth_encoding, layout.big_endian)
            colour_pixels = _colour_pixels(frame.rgb, layout.colour_encoding)
            depth = build.image(
                depth_header, depth_pixels, layout.depth_encoding, layout.row_padding, big
            )
            colour = build.image(
                header, colour_pixels, layout.colour_encoding, layout.row_padding, False
            )
            info = build.camera_info(header, frame.intrinsics, layout.distortion)
            messages = [
                ("depth", image_type, depth),
                ("colour", image_type, colour),
                ("info", "sensor_msgs/msg/CameraInfo", info),
            ]
            messages += [
                (f"extra{k}", image_type, colour) for k in range(len(layout.extra_colour_topics))
            ]
            if layout.pose_topic is not None and frame.pose_gt is not None:
                pose_header = build.header(stamp, "world", number)
                pose = build.pose(pose_header, frame.pose_gt, layout.pose_type)
                messages.append(("pose", _POSE_TYPES[layout.pose_type], pose))
            logged = stamp + 1_000_000  # arrival 1 ms after the stamp
            for offset, (role, msgtype, message) in enumerate(messages):
                writer.write(connections[role], logged + offset, serialize(message, msgtype))
    return path


REALSENSE_DEPTH_UNITS = 0.00025
"""Metres per depth unit :func:`write_realsense_recording` records (a D400's 0.25 mm mode)."""


def _rs_intrinsics(rs, camera: Intrinsics):
    k = rs.intrinsics()
    k.width, k.height = camera.width, camera.height
    k.fx, k.fy, k.ppx, k.ppy = camera.fx, camera.fy, camera.cx, camera.cy
    k.model = rs.distortion.brown_conrady
    k.coeffs = [0.0] * 5
    return k


def write_realsense_recording(
    path: str | Path,
    frames: Sequence[Frame],
    depth_units: float = REALSENSE_DEPTH_UNITS,
    depth_camera: Intrinsics | None = None,
) -> Path:
    """Record ``frames`` with librealsense's recorder from its software device (a .db3).

    Depth and colour sensors stream Z16 and RGB8 at 30 fps; frame n has frame number
    n + 1 on both and time (n + 1) * 33.3 ms. Needs pyrealsense2.

    Args:
        path: the .db3 file to write.
        frames: frames sharing one camera (colour's; also depth's unless ``depth_camera``).
        depth_units: the depth sensor's metres per unit.
        depth_camera: a different depth camera (same centre, identity extrinsics): depth
            is resampled to it (nearest pixel), so playback must align it to colour.

    Returns:
        ``path``.
    """
    from eslam.data.realsense import import_pyrealsense2

    rs = import_pyrealsense2()
    colour_camera = frames[0].intrinsics
    depth_camera = depth_camera or colour_camera
    device = rs.software_device()
    depth_sensor, colour_sensor = device.add_sensor("Depth"), device.add_sensor("Color")
    profiles = []
    for uid, (sensor, kind, camera, fmt, bpp) in enumerate(
        [
            (depth_sensor, rs.stream.depth, depth_camera, rs.format.z16, 2),
            (colour_sensor, rs.stream.color, colour_camera, rs.format.rgb8, 3),
        ]
    ):
        stream = rs.video_stream()
        stream.type, stream.index, stream.uid = kind, 0, uid
        stream.width, stream.height, stream.fps = camera.width, camera.height, 30
        stream.bpp, stream.fmt, stream.intrinsics = bpp, fmt, _rs_intrinsics(rs, camera)
        profiles.append(sensor.add_video_stream(stream))
    depth_sensor.add_read_only_option(rs.option.depth_units, depth_units)
    identity = rs.extrinsics()
    identity.rotation, identity.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
    profiles[0].register_extrinsics_to(profiles[1], identity)
    recorder = rs.recorder(str(path), device)
    depth_sensor.open(profiles[0])
    colour_sensor.open(profiles[1])
    queue = rs.frame_queue(len(frames) * 2 + 2)
    depth_sensor.start(queue)
    colour_sensor.start(queue)
    for number, frame in enumerate(frames):
        depth_m = frame.depth
        if depth_camera != colour_camera:
            v, u = np.mgrid[0 : depth_camera.height, 0 : depth_camera.width]
            cu = np.rint(
                (u - depth_camera.cx) / depth_camera.fx * colour_camera.fx + colour_camera.cx
            )
            cv = np.rint(
                (v - depth_camera.cy) / depth_camera.fy * colour_camera.fy + colour_camera.cy
            )
            cu = np.clip(cu, 0, colour_camera.width - 1).astype(int)
            cv = np.clip(cv, 0, colour_camera.height - 1).astype(int)
            depth_m = depth_m[cv, cu]
        units = np.clip(np.round(np.nan_to_num(depth_m) / depth_units), 0, 65535)
        images = [
            (depth_sensor, profiles[0], np.ascontiguousarray(units.astype(np.uint16)), 2),
            (colour_sensor, profiles[1], np.ascontiguousarray(frame.rgb), 3),
        ]
        for sensor, profile, pixels, bpp in images:
            video = rs.software_video_frame()
            video.pixels, video.bpp, video.stride = pixels, bpp, pixels.shape[1] * bpp
            video.timestamp = (number + 1) * 33.3
            video.domain = rs.timestamp_domain.hardware_clock
            video.frame_number = number + 1
            video.profile = profile.as_video_stream_profile()
            if sensor is depth_sensor:
                video.depth_units = depth_units
            sensor.on_video_frame(video)
        time.sleep(FRAME_PERIOD_NS / 1e9)  # the recorder stamps messages by the clock
    for sensor in (depth_sensor, colour_sensor):
        sensor.stop()
        sensor.close()
    del recorder  # closes the file
    return Path(path)


def write_redwood_folder(
    root: str | Path, frames: Sequence[Frame], camera_json: bool = True, trajectory: bool = True
) -> Path:
    """Write ``frames`` in Open3D's reconstruction-system layout: image/NNNNNN.png,
    depth/NNNNNN.png (millimetres), camera_intrinsic.json and trajectory.log (the poses,
    which every frame must have)."""
    import json

    from PIL import Image

    from eslam.atomic import write_text, write_with

    root = Path(root)
    blocks = []
    for number, frame in enumerate(frames):
        colour, depth = Image.fromarray(frame.rgb), Image.fromarray(depth_millimetres(frame.depth))
        write_with(root / "image" / f"{number:06d}.png", lambda t, i=colour: i.save(t, "PNG"))
        write_with(root / "depth" / f"{number:06d}.png", lambda t, i=depth: i.save(t, "PNG"))
        if trajectory:
            rows = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in frame.pose_gt)
            blocks.append(f"{number} {number} {number + 1}\n{rows}\n")
    camera = frames[0].intrinsics
    if camera_json:
        k = [camera.fx, 0.0, 0.0, 0.0, camera.fy, 0.0, camera.cx, camera.cy, 1.0]
        data = {"width": camera.width, "height": camera.height, "intrinsic_matrix": k}
        write_text(root / "camera_intrinsic.json", json.dumps(data))
    if trajectory:
        write_text(root / "trajectory.log", "".join(blocks))
    return root


_STREAM_INFO = "uint32 fps\nstring encoding\nbool is_recommended\n"
"""librealsense's realsense_msgs/StreamInfo definition."""


def write_realsense_bag(
    path: str | Path, frames: Sequence[Frame], depth_units: float = REALSENSE_DEPTH_UNITS
) -> Path:
    """Write ``frames`` as a ROS 1 ``.bag`` in librealsense's recording layout (its
    ``src/media/readme.md``, as ``ros_reader.cpp`` reads it), with rosbags: the layout
    RealSense Viewer recordings before 2.58 have.

    Per sensor (0: Depth, 1: Color) an info KeyValue, a StreamInfo, the stream's camera
    info ("Brown Conrady", no distortion), an identity transform and per frame an Image
    (depth mono16 in ``depth_units``, colour rgb8) with header seq = frame number
    (n + 1) and stamp = (n + 1) / 30 s. Uncompressed, nothing at bag time 0: librealsense
    rejects both.
    """
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import get_types_from_msg

    store = _typestore("ros1")
    store.register(get_types_from_msg(_STREAM_INFO, "realsense_msgs/msg/StreamInfo"))
    build = _Messages(store, ros1=True)
    types = store.types
    camera = frames[0].intrinsics
    period = 1_000_000_000 // 30

    def key_values(values: dict[str, str]) -> list:
        return [types["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in values.items()]

    static: list[tuple[str, str, object]] = [
        ("/file_version", "std_msgs/msg/UInt32", types["std_msgs/msg/UInt32"](data=3))
    ]
    device = key_values({"Name": "eslam test recording", "Serial Number": "0"})
    static += [("/device_0/info", "diagnostic_msgs/msg/KeyValue", m) for m in device]
    streams = (("sensor_0", "Depth_0", "Depth", "mono16"), ("sensor_1", "Color_0", "Color", "rgb8"))
    for sensor, stream, name, encoding in streams:
        prefix = f"/device_0/{sensor}"
        static += [(f"{prefix}/info", "diagnostic_msgs/msg/KeyValue", m)
                   for m in key_values({"Name": name})]  # fmt: skip
        info = types["realsense_msgs/msg/StreamInfo"](
            fps=30, encoding=encoding, is_recommended=True
        )
        static.append((f"{prefix}/{stream}/info", "realsense_msgs/msg/StreamInfo", info))
        camera_info = build.camera_info(build.header(0, "0"), camera, (0.0,) * 5)
        camera_info.distortion_model = "Brown Conrady"
        static.append(
            (f"{prefix}/{stream}/info/camera_info", "sensor_msgs/msg/CameraInfo", camera_info)
        )
        identity = types["geometry_msgs/msg/Transform"](
            types["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0),
            types["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
        )
        static.append((f"{prefix}/{stream}/tf/0", "geometry_msgs/msg/Transform", identity))
    units = "/device_0/sensor_0/option/Depth Units"
    static.append(
        (f"{units}/value", "std_msgs/msg/Float32", types["std_msgs/msg/Float32"](depth_units))
    )
    meaning = types["std_msgs/msg/String"]("Number of meters represented by a single depth unit")
    static.append((f"{units}/description", "std_msgs/msg/String", meaning))
    path = Path(path)
    with Writer(path) as writer:
        connections: dict[str, object] = {}

        def write(topic: str, msgtype: str, message: object, time_ns: int) -> None:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(connections[topic], time_ns, store.serialize_ros1(message, msgtype))

        for topic, msgtype, message in static:
            write(topic, msgtype, message, 1)  # never at bag time 0
        for number, frame in enumerate(frames):
            stamp = (number + 1) * period
            header = build.header(stamp, "0", number + 1)
            images = (
                ("/device_0/sensor_0/Depth_0/image/data",
                 np.round(np.nan_to_num(frame.depth) / depth_units).astype(np.uint16), "mono16"),
                ("/device_0/sensor_1/Color_0/image/data", frame.rgb, "rgb8"),
            )  # fmt: skip
            for topic, pixels, encoding in images:
                message = build.image(header, np.ascontiguousarray(pixels), encoding, 0, False)
                write(topic, "sensor_msgs/msg/Image", message, stamp)
    return path
