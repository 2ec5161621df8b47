"""TUM RGB-D, in its own layout (with or without ground truth).

Layout::

    ROOT/rgb.txt           '# comments', then 'timestamp filename' per colour image
    ROOT/depth.txt         the same for the depth images
    ROOT/groundtruth.txt   optional: 'timestamp tx ty tz qx qy qz qw' (mocap, ~100 Hz)
    ROOT/rgb/*.png         640x480 colour; ROOT/depth/*.png 640x480 uint16, m = value / 5000

Frames follow the ESLAM release (``TUM_RGBD.loadtum`` and ``associate_frames`` in
src/utils/datasets.py, inherited from NICE-SLAM): each colour image takes the depth
image and the ground-truth pose nearest to it in time; a colour image with no depth (or,
when groundtruth.txt exists, no pose) closer than MAX_TIME_DIFFERENCE is dropped; then
a frame closer than 1 / RELEASE_FRAME_RATE seconds to the last kept one is dropped.
With ``data.pairing: associate`` colour and depth are paired as TUM's own
``associate.py`` does (:mod:`eslam.data.tum_pairs`: every frame it pairs, e.g. 792 of
fr1/xyz's 798 where the release's rule keeps 759), each with its nearest pose.

Time stamps: a frame carries its colour image's time and the ground-truth pose nearest
to it (the release). The Kinect's colour and depth streams are not synchronised (a
frame's two images are up to 20 ms apart under associate.py's pairing); a tracker that
fits the depth estimates the camera when the depth image was taken, so ``data.stamp:
depth`` stamps each frame, and picks its pose, with the depth image's time instead (the
images are the same; docs/data.md, "Time stamps").

Images: fr1 and fr2 colour AND depth are undistorted at 640x480 with the camera's
plumb-bob coefficients (the release undistorts colour only), then resized to 512x384
and cropped by 8 px on every side (release defaults; ``data.resize`` / ``data.crop``
override them). The camera comes from ``data.camera`` or the folder name (freiburg1..3).

Poses: TUM's ground truth is the pose of the colour camera's optical centre in the
motion-capture world (camera-to-world, x right, y down, z forward), i.e. already in
OpenCV axes; the release flips y and z only to reach its own OpenGL convention, so no
axis change happens here. Like the release, poses are re-expressed relative to the
first frame's (world = that camera's frame, frame 0 at identity), which is the frame
the release's scene bounds are given in, and the frame a run without ground truth
starts from. ``mocap_from_world`` maps them back to groundtruth.txt's world.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from eslam.config import DataConfig
from eslam.data.base import FileSequence, FrameReading, require_dir, require_file
from eslam.data.transform import transform_from_options
from eslam.data.tum_pairs import unique_pairs
from eslam.data.undistort import PlumbBob, Undistorter
from eslam.errors import ConfigError, InputError
from eslam.io.pose_files import TUM_COLUMNS, read_pose_table, text_lines, tum_poses
from eslam.types import Frame, Intrinsics

TUM_DEPTH_SCALE = 5000.0
"""Depth PNG units per metre (TUM RGB-D file formats page; release tum.yaml png_depth_scale)."""
TUM_RESIZE = (512, 384)
"""Default resize (width, height): the release's cam.crop_size [384, 512] (a resize)."""
TUM_CROP = 8
"""Default border crop after the resize, pixels: the release's cam.crop_edge for TUM."""
MAX_TIME_DIFFERENCE = 0.08
"""Largest colour-depth and colour-pose time difference, s (release associate_frames max_dt)."""
RELEASE_FRAME_RATE = 32.0
"""Frames closer than 1 / this many seconds to the last kept one are dropped (release
loadtum(frame_rate=32)); TUM records at 30 Hz, so this only removes jittered duplicates."""
QUATERNION_NORM_TOLERANCE = 0.01
"""Largest | |q| - 1 | accepted in groundtruth.txt (TUM writes 4 decimals: |q| is 1 +- 1e-4)."""


@dataclass(frozen=True)
class TUMCamera:
    """One of TUM RGB-D's three Kinects.

    Attributes:
        name: fr1, fr2 or fr3.
        intrinsics: 640x480 pinhole intrinsics of the colour camera.
        distortion: plumb-bob coefficients, or None (fr3 images are undistorted already).
    """

    name: str
    intrinsics: Intrinsics
    distortion: PlumbBob | None


TUM_CAMERAS = {
    # TUM RGB-D "camera calibration" page; the same numbers as the ESLAM release's
    # configs/TUM_RGBD/freiburg{1_desk,2_xyz,3_office}.yaml (docs/method.md section 9).
    "fr1": TUMCamera(
        "fr1",
        Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3),
        PlumbBob(0.2624, -0.9531, -0.0054, 0.0026, 1.1633),
    ),
    "fr2": TUMCamera(
        "fr2",
        Intrinsics(640, 480, 520.9, 521.0, 325.1, 249.7),
        PlumbBob(0.2312, -0.7849, -0.0033, -0.0001, 0.9172),
    ),
    "fr3": TUMCamera("fr3", Intrinsics(640, 480, 535.4, 539.2, 320.1, 247.6), None),
}
"""The TUM cameras by the name ``data.camera`` takes."""

_FOLDER_CAMERA = re.compile(r"(?:^|[^a-z])(?:freiburg|fr)([123])(?!\d)", re.IGNORECASE)


def camera_for(root: Path, name: str | None) -> TUMCamera:
    """The camera named ``name`` (fr1|fr2|fr3), else the one the folder name says.

    Raises:
        ConfigError: an unknown name, or no name and no freiburg1/2/3 in the folder name.
    """
    if name is not None:
        try:
            return TUM_CAMERAS[name.lower()]
        except KeyError:
            raise ConfigError(
                f"unknown TUM camera data.camera='{name}' (choose one of: fr1, fr2, fr3)"
            ) from None
    match = _FOLDER_CAMERA.search(root.resolve().name)
    if match is None:
        raise ConfigError(
            f"{root}: cannot tell the TUM camera from the folder name (no 'freiburg1', "
            "'freiburg2' or 'freiburg3'): set data.camera to fr1, fr2 or fr3"
        )
    return TUM_CAMERAS[f"fr{match.group(1)}"]


def _timestamp(path: Path, number: int, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise InputError(path, f"line {number}: timestamp '{text}' is not a finite number")
    return value


@dataclass(frozen=True)
class FileList:
    """A TUM image list (rgb.txt or depth.txt).

    Attributes:
        path: the list file.
        timestamps: (N,) float64 seconds.
        paths: N image paths, resolved against the list's folder.
    """

    path: Path
    timestamps: np.ndarray
    paths: tuple[Path, ...]


def read_file_list(path: Path, what: str) -> FileList:
    """Read rgb.txt or depth.txt ('timestamp filename' lines); ``what`` names the images."""
    require_file(path, f"the TUM list of {what} ('timestamp filename' per line)")
    times: list[float] = []
    paths: list[Path] = []
    for number, text in text_lines(path):
        fields = text.split()
        if len(fields) != 2:
            raise InputError(
                path, f"line {number}: expected 'timestamp filename', got {len(fields)} fields"
            )
        times.append(_timestamp(path, number, fields[0]))
        paths.append(path.parent / fields[1])
    if not times:
        raise InputError(path, f"lists no {what}")
    return FileList(path, np.array(times, dtype=np.float64), tuple(paths))


@dataclass(frozen=True)
class Groundtruth:
    """TUM ground truth (groundtruth.txt).

    Attributes:
        path: the file.
        timestamps: (M,) float64 seconds.
        poses: (M, 4, 4) float64 camera-to-world poses in the mocap world, OpenCV axes.
    """

    path: Path
    timestamps: np.ndarray
    poses: np.ndarray


def read_groundtruth(path: Path) -> Groundtruth:
    """Read 'timestamp tx ty tz qx qy qz qw' lines (:mod:`eslam.io.pose_files`).

    Raises:
        InputError: naming the line of a wrong field count, a non-number, a non-finite
            value or a quaternion whose norm is not 1 within QUATERNION_NORM_TOLERANCE.
    """
    table = read_pose_table(path, (TUM_COLUMNS,))
    times, poses = tum_poses(table, quaternion_tolerance=QUATERNION_NORM_TOLERANCE)
    return Groundtruth(path, times, poses)


def nearest(times: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Index into ``times`` of the time nearest to each query (the earlier one on ties).

    Matches the release's ``np.argmin(np.abs(times - t))`` for sorted ``times``.

    Args:
        times: (M,) float64 seconds, any order.
        queries: (N,) float64 seconds.

    Returns:
        (N,) int64 indices into ``times``.
    """
    order = np.argsort(times, kind="stable")
    ordered = times[order]
    right = np.clip(np.searchsorted(ordered, queries, side="left"), 0, len(ordered) - 1)
    left = np.clip(right - 1, 0, len(ordered) - 1)
    take_left = np.abs(queries - ordered[left]) <= np.abs(ordered[right] - queries)
    return order[np.where(take_left, left, right)]


@dataclass(frozen=True)
class Association:
    """Which colour image, depth image and ground-truth pose make each frame.

    Attributes:
        colour: (N,) int64 rows of rgb.txt.
        depth: (N,) int64 rows of depth.txt.
        pose: (N,) int64 rows of groundtruth.txt, or None without ground truth.
    """

    colour: np.ndarray
    depth: np.ndarray
    pose: np.ndarray | None


def associate(
    colour_times: np.ndarray,
    depth_times: np.ndarray,
    pose_times: np.ndarray | None,
    max_dt: float = MAX_TIME_DIFFERENCE,
    frame_rate: float = RELEASE_FRAME_RATE,
    pairing: str = "release",
    stamp: str = "colour",
) -> Association:
    """Pair every colour image with the nearest depth image and pose, as the release.

    A colour image is kept when its nearest depth (and pose, if given) is strictly
    closer than ``max_dt`` seconds, and when it comes more than 1 / ``frame_rate``
    seconds after the previous kept one (release ``loadtum``). With ``pairing``
    "associate" the colour-depth pairs are TUM's ``associate.py``'s
    (:func:`~eslam.data.tum_pairs.unique_pairs`) and each keeps the nearest pose closer
    than ``max_dt`` (no frame-rate rule). The pose is the one nearest the colour image's
    time, or with ``stamp`` "depth" the depth image's (``data.stamp``).

    Args:
        colour_times: (N,) seconds, in rgb.txt order.
        depth_times: (M,) seconds.
        pose_times: (K,) seconds, or None without ground truth.
        max_dt: largest time difference, seconds.
        frame_rate: highest frame rate kept, Hz.
        pairing: "release" or "associate" (``data.pairing``).
        stamp: "colour" or "depth": whose time the pose is matched to (``data.stamp``).
    """
    if stamp not in ("colour", "depth"):
        raise ValueError(f"stamp must be 'colour' or 'depth', got {stamp!r}")
    if pairing == "associate":
        colour, depth = unique_pairs(colour_times, depth_times)
        if pose_times is None:
            return Association(colour, depth, None)
        times = colour_times[colour] if stamp == "colour" else depth_times[depth]
        pose = nearest(pose_times, times)
        timed = np.abs(pose_times[pose] - times) < max_dt
        return Association(colour[timed], depth[timed], pose[timed])
    depth = nearest(depth_times, colour_times)
    matched = np.abs(depth_times[depth] - colour_times) < max_dt
    pose = None
    if pose_times is not None:
        times = colour_times if stamp == "colour" else depth_times[depth]
        pose = nearest(pose_times, times)
        matched &= np.abs(pose_times[pose] - times) < max_dt
    kept: list[int] = []
    for index in np.flatnonzero(matched):
        if not kept or colour_times[index] - colour_times[kept[-1]] > 1.0 / frame_rate:
            kept.append(int(index))
    rows = np.array(kept, dtype=np.int64)
    return Association(rows, depth[rows], None if pose is None else pose[rows])


def _require_images(paths: Sequence[Path], listed_in: Path, partner: str) -> None:
    for path in paths:
        if not path.is_file():
            raise InputError(
                path,
                f"listed in {listed_in.name} (paired with {partner}) but not found",
                f"restore the image or remove its line from {listed_in.name}",
            )


class TUMSequence(FileSequence):
    """Reader of a TUM RGB-D folder (see the module docstring).

    Args:
        root: the sequence folder (rgb.txt, depth.txt, optional groundtruth.txt, images).
        options: the ``data`` config section: depth_scale (default 5000), resize
            (default 512x384), crop (default 8) and camera (default from the folder name).

    Attributes:
        camera: the TUM camera used (intrinsics and distortion of the 640x480 images).
        intrinsics: intrinsics of the frames delivered (after resize and crop).
        mocap_from_world: (4, 4) pose of the world frame (the first frame's camera) in
            groundtruth.txt's world, or None without ground truth.
        dropped: number of colour images left out (no depth or pose in time, or too close).

    Raises:
        ConfigError: unknown camera, or none given and none in the folder name.
        InputError: missing folder or list, a bad line (named), a listed image that is
            missing, no colour image with a depth image in time, or bad ground truth.
    """

    def __init__(self, root: str | Path, options: DataConfig | None = None) -> None:
        options = options or DataConfig()
        self.root = require_dir(Path(root), "a TUM RGB-D sequence: rgb.txt, depth.txt, images")
        self.camera = camera_for(self.root, options.camera)
        self.depth_scale = options.depth_scale or TUM_DEPTH_SCALE
        self.transform = transform_from_options(
            options.resize, options.crop, default_size=TUM_RESIZE, default_crop=TUM_CROP
        )
        distortion = self.camera.distortion
        self._undistort = (
            Undistorter(self.camera.intrinsics, distortion)
            if distortion is not None and not distortion.is_identity
            else None
        )
        self.reading = FrameReading(
            self.camera.intrinsics,
            self.depth_scale,
            self.transform,
            prepare=None if self._undistort is None else self._undistort.images,
        )
        self.intrinsics = self.reading.intrinsics
        colour = read_file_list(self.root / "rgb.txt", "colour images")
        depth = read_file_list(self.root / "depth.txt", "depth images")
        gt_path = self.root / "groundtruth.txt"
        groundtruth = read_groundtruth(gt_path) if gt_path.exists() else None
        pairs = associate(
            colour.timestamps,
            depth.timestamps,
            None if groundtruth is None else groundtruth.timestamps,
            pairing=options.pairing,
            stamp=options.stamp,
        )
        if len(pairs.colour) == 0:
            with_pose = "" if groundtruth is None else f" and a pose in {gt_path.name}"
            raise InputError(
                colour.path,
                f"no colour image has a depth image{with_pose} within {MAX_TIME_DIFFERENCE} s",
                "check that rgb.txt, depth.txt and groundtruth.txt come from one recording",
            )
        self.dropped = len(colour.timestamps) - len(pairs.colour)
        self._times = (
            colour.timestamps[pairs.colour]
            if options.stamp == "colour"
            else depth.timestamps[pairs.depth]
        )
        self._colour_delays = colour.timestamps[pairs.colour] - depth.timestamps[pairs.depth]
        self._colour_paths = [colour.paths[i] for i in pairs.colour]
        self._depth_paths = [depth.paths[i] for i in pairs.depth]
        _require_images(self._colour_paths, colour.path, "a depth image")
        _require_images(self._depth_paths, depth.path, "a colour image")
        self._poses: np.ndarray | None = None
        self.mocap_from_world: np.ndarray | None = None
        if groundtruth is not None and pairs.pose is not None:
            poses = groundtruth.poses[pairs.pose]
            self.mocap_from_world = poses[0].copy()
            self._poses = _relative_to(poses[0], poses)

    def __getitem__(self, index: int) -> Frame:
        """Frame ``index`` with its colour image's delay after its depth image."""
        frame = super().__getitem__(index)
        return replace(frame, colour_delay=float(self._colour_delays[index]))


def _relative_to(reference: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """reference^-1 @ poses for a rigid (4, 4) reference and (N, 4, 4) poses, float64."""
    inverse = np.eye(4)
    inverse[:3, :3] = reference[:3, :3].T
    inverse[:3, 3] = -reference[:3, :3].T @ reference[:3, 3]
    return inverse @ poses
