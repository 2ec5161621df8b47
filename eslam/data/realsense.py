"""Intel RealSense input: recordings (``data.format: realsense``) and the live camera.

Both need the ``realsense`` extra (``pip install "eslam[realsense]"``; on Linux also the
system library libusb: ``sudo apt-get install -y libusb-1.0-0``); pyrealsense2 is
imported only here, when a RealSense input is opened.

Recordings (librealsense's ``.bag``, or the ``.db3`` its recorder writes since 2.58)
are played back without a camera and not in real time, so no frame is lost to a slow
reader. Opening one plays it through once to index every depth and colour frame (frame
number and time); colour and depth are paired by time (mutual nearest within
:data:`PAIR_TOLERANCE_S`, :func:`eslam.data.rosbag.pair_by_stamp`), never by arrival
order: the SDK's framesets repeat frames in playback (d1/c1, d2/c1, d2/c2) and leave
the first ones unpaired. A frame is then decoded by playing on from the last one read
(an earlier frame: from the start again).

Depth is aligned to colour with ``rs.align(rs.stream.color)``, unless the recording's
depth already is registered to colour (same intrinsics, identity extrinsics), where
alignment would only add resampling holes. Depth is the device's units times its
depth scale (``data.depth_scale`` overrides it); intrinsics are the colour stream's.
Timestamps are the colour frames' (seconds).

The live camera (:class:`RealSenseCamera`, ``eslam run --source realsense[:SERIAL]``)
is a :class:`~eslam.data.source.FrameSource`: frames in order, no length.

Over 400 lines on purpose: the recorded (.bag/.db3) reader and the live camera share
the sensor's conventions (depth units, streams, intrinsics, alignment) in one place.
"""

from __future__ import annotations

import contextlib
import datetime
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.config import DataConfig
from eslam.data.base import FrameReading
from eslam.data.rosbag import pair_by_stamp
from eslam.data.transform import transform_from_options
from eslam.data.undistort import PlumbBob, Undistorter
from eslam.errors import ConfigError, InputError
from eslam.types import Frame, Intrinsics

INSTALL_HINT = (
    'pip install "eslam[realsense]" (pyrealsense2; on Linux also '
    "sudo apt-get install -y libusb-1.0-0)"
)
"""How to get RealSense support, as every import error says."""

CAMERA_WAIT_MS = 5000
"""How long a live camera may send nothing before the run stops with an error, ms."""

LIVE_NAME = "realsense"
"""What messages call the live camera (with ``:SERIAL`` when one was named)."""


def import_pyrealsense2():
    """The pyrealsense2 module, or a ConfigError naming the extra and the libusb step."""
    try:
        import pyrealsense2
    except ImportError as error:
        reason = (
            "its system library libusb is missing" if "libusb" in str(error) else "not installed"
        )
        raise ConfigError(f"RealSense input needs pyrealsense2, {reason}: {INSTALL_HINT}") from None
    return pyrealsense2


@dataclass(frozen=True)
class StreamCamera:
    """A stream's camera as the SDK reports it: pinhole intrinsics and distortion."""

    intrinsics: Intrinsics
    distortion: PlumbBob | None


def stream_camera(rs, profile, where: str | Path) -> StreamCamera:
    """The camera of a video stream profile; distortion other than Brown-Conrady (OpenCV's
    plumb bob) with non-zero coefficients is refused."""
    k = profile.as_video_stream_profile().get_intrinsics()
    intrinsics = Intrinsics(int(k.width), int(k.height), float(k.fx), float(k.fy),
                            float(k.ppx), float(k.ppy))  # fmt: skip
    coeffs = [float(c) for c in k.coeffs]
    if not any(coeffs):
        return StreamCamera(intrinsics, None)
    if k.model != rs.distortion.brown_conrady:
        raise InputError(
            where,
            f"colour distortion {k.model} with coefficients {coeffs} cannot be undone "
            "(eslam undistorts Brown-Conrady)",
            "record rectified colour",
        )
    return StreamCamera(intrinsics, PlumbBob(*coeffs[:5]))


def _registered(rs, depth_profile, colour_profile) -> bool:
    """Whether depth already is in the colour camera (same intrinsics, no offset)."""
    depth = depth_profile.as_video_stream_profile().get_intrinsics()
    colour = colour_profile.as_video_stream_profile().get_intrinsics()
    same = all(
        getattr(depth, name) == getattr(colour, name)
        for name in ("width", "height", "fx", "fy", "ppx", "ppy")
    ) and list(depth.coeffs) == list(colour.coeffs)
    try:
        extrinsics = depth_profile.get_extrinsics_to(colour_profile)
    except RuntimeError:  # none recorded: rs.align decides what it can do
        return False
    identity = np.allclose(np.reshape(extrinsics.rotation, (3, 3)), np.eye(3)) and np.allclose(
        extrinsics.translation, 0.0
    )
    return same and identity


PAIR_TOLERANCE_S = 0.02
"""Largest time difference of a colour and a depth frame paired into one frame, s."""

ARRIVAL_QUEUE = 8
"""Framesets the playback may run ahead of the reader (it waits while they are unread).
Below the SDK's frame pool of 16 per stream: with 16 queued, later frames were dropped."""

END_GRACE_S = 0.2
"""How long to wait for a last frame after the playback reports it stopped, s."""


@dataclass(frozen=True)
class FramePair:
    """One frame of a recording: its depth and colour frame numbers, colour time (ms)."""

    depth: int
    colour: int
    colour_ms: float


class _Player:
    """A recording played from its start, not in real time: its depth and colour frames
    in file order, each once.

    The SDK's syncer is the sensors' sink (a C++ queue: non-real-time playback waits
    while :data:`ARRIVAL_QUEUE` framesets are unread); its framesets are taken apart,
    since it does not pair the first frames. The sensors start in real time (starting
    the first one starts the playback, so a non-real-time playback could race past the
    second one's first frames), then playback goes non-real-time and back to the start;
    frames seen before that are skipped when they come again. (Pausing instead made
    ``resume()`` hang for 10 s now and then, with pyrealsense2 2.59.)
    """

    def __init__(self, rs, path: Path) -> None:
        self.rs = rs
        try:
            device = rs.context().load_device(str(path))
        except RuntimeError as error:
            raise InputError(path, f"not a readable RealSense recording ({error})") from None
        self.playback = device.as_playback()
        self.sensors = device.query_sensors()
        self.profiles = [p for s in self.sensors for p in s.get_stream_profiles()]
        self.syncer = rs.syncer(ARRIVAL_QUEUE)
        self.running = True
        for sensor in self.sensors:
            sensor.open(sensor.get_stream_profiles())
        for sensor in self.sensors:
            sensor.start(self.syncer)
        self.playback.set_real_time(False)
        self.playback.seek(datetime.timedelta(0))

    def frames(self) -> Iterator:
        """The depth and colour frames, in file order, until the recording ends."""
        stopped = self.rs.playback_status.stopped
        kinds = (self.rs.stream.depth, self.rs.stream.color)
        seen: set[tuple[bool, int]] = set()
        while True:
            ok, frames = self.syncer.try_wait_for_frames(50)
            if not ok and self.playback.current_status() == stopped:
                ok, frames = self.syncer.try_wait_for_frames(round(END_GRACE_S * 1000))
                if not ok:
                    return
            if not ok:
                continue
            for frame in frames:
                kind = frame.profile.stream_type()
                key = (kind == self.rs.stream.depth, frame.get_frame_number())
                if kind in kinds and key not in seen:
                    seen.add(key)
                    yield frame

    def stop(self) -> None:
        if not self.running:
            return
        self.running = False
        for sensor in self.sensors:
            with contextlib.suppress(RuntimeError):
                sensor.stop()
        for sensor in self.sensors:
            with contextlib.suppress(RuntimeError):
                sensor.close()


def _frameset(rs, frames: list):
    """A frameset (composite frame) of ``frames``, as rs.align takes it."""
    made = []

    def combine(frame, source) -> None:
        source.frame_ready(source.allocate_composite_frame(frames))

    block = rs.processing_block(combine)
    block.start(made.append)
    block.invoke(frames[-1])
    return made[0].as_frameset()


class RealSenseRecording:
    """Frames of a RealSense ``.bag`` / ``.db3`` recording (module doc).

    Args:
        root: the recording file.
        options: the ``data`` config section; depth_scale (default: the device's),
            resize and crop apply.

    Raises:
        ConfigError: pyrealsense2 is missing (the message says how to install it).
        InputError: not a recording, no depth or no colour stream, or no frames.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = Path(root)
        if not self.root.is_file():
            raise InputError(self.root, "recording not found", "check the --data path")
        self.rs = import_pyrealsense2()
        player = _Player(self.rs, self.root)
        try:
            self._describe(player, options)
            seen: dict[tuple[bool, int], float] = {}
            for frame in player.frames():
                key = (
                    frame.profile.stream_type() == self.rs.stream.depth,
                    frame.get_frame_number(),
                )
                seen.setdefault(key, frame.get_timestamp())
        finally:
            player.stop()
        colour = sorted((ms, n) for (is_depth, n), ms in seen.items() if not is_depth)
        depth = sorted((ms, n) for (is_depth, n), ms in seen.items() if is_depth)
        pairs = pair_by_stamp(
            np.array([round(ms * 1000) for ms, _ in colour], dtype=np.int64),
            np.array([round(ms * 1000) for ms, _ in depth], dtype=np.int64),
            round(PAIR_TOLERANCE_S * 1e6),
        )
        self._pairs = [FramePair(depth[j][1], colour[i][1], colour[i][0]) for i, j in pairs]
        if not self._pairs:
            raise InputError(
                self.root,
                f"holds no colour frame with a depth frame within {PAIR_TOLERANCE_S * 1000:g} ms",
                "record depth and colour together",
            )
        self._times = np.array([p.colour_ms for p in self._pairs], dtype=np.float64) / 1000.0
        self._player: _Player | None = None
        self._next = 0  # the pair the open player reaches next
        self._pending: dict[tuple[bool, int], object] = {}

    def _describe(self, player: _Player, options: DataConfig) -> None:
        rs = self.rs
        streams = {p.stream_type(): p for p in player.profiles}
        if rs.stream.depth not in streams or rs.stream.color not in streams:
            found = ", ".join(sorted(str(s) for s in streams)) or "none"
            raise InputError(
                self.root,
                f"needs a depth and a colour stream, holds {found}",
                "record with both streams enabled",
            )
        depth_profile, colour_profile = streams[rs.stream.depth], streams[rs.stream.color]
        camera = stream_camera(rs, colour_profile, self.root)
        depth_sensors = [s for s in player.sensors if s.is_depth_sensor()]
        if not depth_sensors:
            raise InputError(self.root, "has no depth sensor (no depth scale)")
        self.device_depth_scale = float(depth_sensors[0].as_depth_sensor().get_depth_scale())
        self.depth_scale = options.depth_scale or 1.0 / self.device_depth_scale
        self._align = None
        if not _registered(rs, depth_profile, colour_profile):
            self._align = rs.align(rs.stream.color)
        prepare = None
        if camera.distortion is not None:
            prepare = Undistorter(camera.intrinsics, camera.distortion).images
        self.reading = FrameReading(
            camera.intrinsics,
            self.depth_scale,
            transform_from_options(options.resize, options.crop),
            prepare=prepare,
        )
        self.raw_intrinsics = camera.intrinsics
        self.intrinsics = self.reading.intrinsics

    def __len__(self) -> int:
        return len(self._pairs)

    def _frames_of(self, index: int) -> tuple[object, object]:
        """The (depth, colour) frames of pair ``index``, played on to (or from the start)."""
        if self._player is None or index < self._next:
            self.close()
            self._player = _Player(self.rs, self.root)
            self._stream = self._player.frames()
            self._pending = {}
        pair = self._pairs[index]
        wanted = {(True, pair.depth), (False, pair.colour)}
        later = {(True, p.depth) for p in self._pairs[index + 1 :]}
        later |= {(False, p.colour) for p in self._pairs[index + 1 :]}
        while not wanted <= self._pending.keys():
            frame = next(self._stream, None)
            if frame is None:
                self.close()
                raise InputError(
                    self.root,
                    f"playback ended before depth frame {pair.depth} and colour frame "
                    f"{pair.colour} (frame {index}) came again",
                    "the recording may be damaged; re-record it",
                )
            key = (frame.profile.stream_type() == self.rs.stream.depth, frame.get_frame_number())
            if key in wanted or key in later:
                self._pending[key] = frame
        depth = self._pending.pop((True, pair.depth))
        colour = self._pending.pop((False, pair.colour))
        self._next = index + 1
        return depth, colour

    def __getitem__(self, index: int) -> Frame:
        if not 0 <= index < len(self):
            raise IndexError(f"frame {index} out of range for {len(self)} frames")
        depth, colour = self._frames_of(index)
        if self._align is not None:
            aligned = self._align.process(_frameset(self.rs, [depth, colour]))
            depth = aligned.get_depth_frame()
        rgb = np.asanyarray(colour.get_data()).copy()
        units = np.asanyarray(depth.get_data()).astype(np.float32)
        where = f"{self.root} [frame {index}]"
        return self.reading.build(index, (rgb, units), None, self._times[index], (where, where))

    def gt_poses(self) -> None:
        """Recordings have no ground truth."""
        return None

    def timestamps(self) -> np.ndarray:
        """(N,) colour frame times, seconds."""
        return self._times.copy()

    def frame_files(self, index: int) -> tuple[Path, Path]:
        """The recording holds every frame: (file, file), for the input fingerprint."""
        return self.root, self.root

    def close(self) -> None:
        """Stop the playback (a later read starts it again)."""
        if self._player is not None:
            self._player.stop()
            self._player = None
            self._pending = {}


def parse_source(text: str) -> str | None:
    """The serial number of ``realsense:SERIAL`` (None for plain ``realsense``).

    Raises:
        ConfigError: not a RealSense source.
    """
    name, colon, serial = text.partition(":")
    if name != LIVE_NAME or (colon and not serial):
        raise ConfigError(f"--source must be realsense or realsense:SERIAL, got '{text}'")
    return serial or None


class RealSenseCamera:
    """A live RealSense camera as a frame source: depth aligned to colour, in order.

    The camera starts streaming when this is created (the intrinsics are the colour
    stream's as the device reports them) and stops when the iteration ends or
    :meth:`close` is called. A frameset repeating the previous colour frame is skipped.

    Args:
        serial: the camera's serial number; None = the only camera attached.
        size: (width, height) of both streams.
        fps: frames per second of both streams.
        options: the ``data`` config section: resize and crop apply to the frames.

    Raises:
        ConfigError: pyrealsense2 is missing.
        InputError: no camera found, the serial is not attached, or the camera refuses
            the size and rate.
    """

    live = True
    """A sensor: runs on it are always real-time (eslam.data.feed.is_live)."""

    def __init__(
        self,
        serial: str | None = None,
        size: tuple[int, int] = (640, 480),
        fps: int = 30,
        options: DataConfig | None = None,
    ) -> None:
        options = options or DataConfig()
        rs = import_pyrealsense2()
        self.rs = rs
        self.name = LIVE_NAME if serial is None else f"{LIVE_NAME}:{serial}"
        where = Path(self.name)
        attached = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
        if not attached:
            raise InputError(
                where,
                "no RealSense camera found",
                "plug it into a USB 3 port, check `rs-enumerate-devices`, or pass --data REC.bag",
            )
        if serial is not None and serial not in attached:
            raise InputError(
                where, f"camera not attached (found: {', '.join(attached)})", "check the serial"
            )
        width, height = size
        config = rs.config()
        if serial is not None:
            config.enable_device(serial)
        config.enable_stream(rs.stream.depth, width, height, rs.format.z16, fps)
        config.enable_stream(rs.stream.color, width, height, rs.format.rgb8, fps)
        self._pipeline = rs.pipeline()
        try:
            profile = self._pipeline.start(config)
        except RuntimeError as error:
            raise InputError(
                where,
                f"cannot stream depth and colour at {width}x{height} {fps} fps ({error})",
                "choose a mode the camera offers (--camera-size, --camera-fps)",
            ) from None
        self._running = True
        colour = profile.get_stream(rs.stream.color)
        camera = stream_camera(rs, colour, where)
        self.depth_scale = 1.0 / float(profile.get_device().first_depth_sensor().get_depth_scale())
        prepare = None
        if camera.distortion is not None:
            prepare = Undistorter(camera.intrinsics, camera.distortion).images
        transform = transform_from_options(options.resize, options.crop)
        self._reading = FrameReading(
            camera.intrinsics, self.depth_scale, transform, prepare=prepare
        )
        self.intrinsics = self._reading.intrinsics
        self._align = rs.align(rs.stream.color)

    def __iter__(self) -> Iterator[Frame]:
        index, last = 0, None
        try:
            while True:
                ok, frames = self._pipeline.try_wait_for_frames(CAMERA_WAIT_MS)
                if not ok:
                    raise InputError(
                        Path(self.name),
                        f"sent no frames for {CAMERA_WAIT_MS / 1000:g} s",
                        "check the USB connection",
                    )
                frames = self._align.process(frames)
                depth, colour = frames.get_depth_frame(), frames.get_color_frame()
                if not depth or not colour or colour.get_frame_number() == last:
                    continue
                last = colour.get_frame_number()
                rgb = np.asanyarray(colour.get_data()).copy()
                units = np.asanyarray(depth.get_data()).astype(np.float32)
                where = f"{self.name} [frame {index}]"
                timestamp = colour.get_timestamp() / 1000.0
                yield self._reading.build(index, (rgb, units), None, timestamp, (where, where))
                index += 1
        finally:
            self.close()

    def close(self) -> None:
        """Stop streaming."""
        if self._running:
            self._running = False
            self._pipeline.stop()


def open_camera(spec: str, size: tuple[int, int], fps: int, options: DataConfig) -> RealSenseCamera:
    """The live camera ``eslam run --source realsense[:SERIAL]`` names (``options``:
    the run's ``data`` section, whose path must be unset; its resize and crop apply).

    Raises:
        ConfigError: not a RealSense source, or --data given as well.
        InputError: no such camera (:class:`RealSenseCamera`).
    """
    serial = parse_source(spec)
    if options.path is not None:
        raise ConfigError(
            f"--source {spec} and data.path={options.path} exclude each other: pass one input"
        )
    return RealSenseCamera(serial, size, fps, options)
