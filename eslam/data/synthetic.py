"""Synthetic RGB-D sequences with exact ground truth, written in the Replica layout.

A seeded procedural room (see :func:`build_room`) is ray cast exactly
(:mod:`eslam.data.synthetic_scene`) along a smooth hand-held-like trajectory. The output
folder reads back with :class:`~eslam.data.replica.ReplicaSequence` and also holds the
ground-truth ``mesh.ply`` in the same world frame (metres, z up, floor at z = 0) and
``synth.json`` with the configuration used. Poses are camera-to-world, OpenCV camera
axes. Everything is deterministic for a seed; frame i does not depend on the number of
frames, so a short sequence is a prefix of a long one.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from eslam.atomic import atomic_directory, write_text
from eslam.data.replica import REPLICA_DEPTH_SCALE, write_replica_sequence
from eslam.data.synthetic_materials import random_material
from eslam.data.synthetic_mesh import scene_mesh
from eslam.data.synthetic_scene import (
    Box,
    Cylinder,
    RenderedView,
    RoomBox,
    Scene,
    Sphere,
    render_view,
)
from eslam.errors import InputError
from eslam.io.mesh_files import write_mesh_ply
from eslam.types import Frame, Intrinsics

FPS = 30.0
"""Frame rate of the synthetic camera: timestamp = index / FPS seconds."""
KINECT_AXIAL_NOISE = (0.0012, 0.0019, 0.4)
"""(a, b, z0) of sigma(z) = a + b (z - z0)^2 m: Nguyen, Izadi, Lovell, 3DIMPVT 2012."""
MISSING_FRACTION = 0.02
"""Fraction of pixels dropped at random when ``missing_depth`` is on."""
GRAZING_COSINE = math.cos(math.radians(78.0))
"""Depth is missing where |cos(ray, normal)| is below this (grazing surfaces)."""
EDGE_JUMP = 0.05
"""Depth is missing beside a jump larger than this fraction of the depth (discontinuities)."""
OBJECT_CLEARANCE = 0.7
"""Horizontal gap (m) between the camera's box and any object: depth stays >= 0.5 m."""
WALL_GAP = 0.08
"""Gap (m) between objects and walls, and (twice) between objects."""


@dataclass(frozen=True)
class SynthConfig:
    """What to generate; every field has a safe default."""

    frames: int = 60
    """Number of frames."""
    width: int = 640
    """Image width, pixels."""
    height: int = 480
    """Image height, pixels."""
    seed: int = 0
    """Seed of the scene, the trajectory and the sensor noise."""
    scene: str = "room"
    """Scene builder, a key of SCENES."""
    hfov_deg: float = 65.0
    """Horizontal field of view, degrees (fx = fy; square pixels)."""
    step_translation: float = 0.01
    """Mean camera translation per frame, m (it varies by +-30 % along the way)."""
    step_rotation_deg: float = 0.5
    """Typical camera rotation per frame, degrees (yaw sweep plus pitch and roll sway)."""
    depth_noise: bool = False
    """Add Kinect-like axial noise, sigma(z) from KINECT_AXIAL_NOISE (seeded)."""
    missing_depth: bool = False
    """Drop MISSING_FRACTION of the pixels at random plus grazing and edge pixels (seeded)."""

    def __post_init__(self) -> None:
        if self.frames < 1 or self.width < 2 or self.height < 2:
            raise ValueError(
                f"need frames >= 1 and size >= 2x2, got {self.frames} frames "
                f"of {self.width}x{self.height}"
            )
        if not 1.0 < self.hfov_deg < 170.0:
            raise ValueError(f"hfov_deg must be in (1, 170), got {self.hfov_deg}")
        if self.step_translation <= 0 or self.step_rotation_deg <= 0:
            raise ValueError("step_translation and step_rotation_deg must be positive")
        _scene_builder(self.scene)


def synthetic_intrinsics(config: SynthConfig) -> Intrinsics:
    """Pinhole intrinsics of the synthetic camera: fx = fy from hfov, centred principal point."""
    focal = 0.5 * config.width / math.tan(math.radians(config.hfov_deg) / 2.0)
    return Intrinsics(
        config.width, config.height, focal, focal, (config.width - 1) / 2, (config.height - 1) / 2
    )


def _free(lo: np.ndarray, hi: np.ndarray, boxes: list[tuple[np.ndarray, np.ndarray]]) -> bool:
    """Whether the box [lo, hi] keeps 2 WALL_GAP from every box in ``boxes``."""
    gap = 2 * WALL_GAP
    return all(np.any((lo >= b_hi + gap) | (hi <= b_lo - gap)) for b_lo, b_hi in boxes)


def build_room(rng: np.random.Generator) -> Scene:
    """A closed room (4.5-6 x 3.5-5 x 2.5-3 m) around a free central area for the camera.

    On the floor: 4 boxes (one rotated about z, one carrying a sphere), 2 capped
    cylinders and 2 spheres; on the walls: 2 flat boxes (cabinets). Every surface has
    its own material with a distinct hue. The camera box is centred at 1.3-1.7 m
    height, OBJECT_CLEARANCE (horizontally) from every object.
    """
    size = np.array([rng.uniform(4.5, 6.0), rng.uniform(3.5, 5.0), rng.uniform(2.5, 3.0)])
    half = size / 2
    camera_half = np.array([0.1 * size[0], 0.08 * size[1]])
    keep_out = camera_half + OBJECT_CLEARANCE
    # 18 hue slots 20 degrees apart, neighbours alternating dark and bright
    slots = rng.permutation(18)
    looks = iter(zip(slots / 18 + rng.uniform(), np.where(slots % 2 == 0, 0.58, 0.82), strict=True))
    room = RoomBox(
        np.array([-half[0], -half[1], 0.0]),
        np.array([half[0], half[1], size[2]]),
        tuple(random_material(rng, *next(looks), rng.uniform(0.35, 0.55)) for _ in range(6)),
    )
    objects: list = []
    boxes: list[tuple[np.ndarray, np.ndarray]] = []  # bounds of everything placed

    def material():
        return random_material(rng, *next(looks), rng.uniform(0.6, 0.85))

    def spot(radius: float, top: float) -> tuple[np.ndarray, float]:
        """A floor position for a footprint circle of ``radius`` (shrunk until one fits)."""
        for _ in range(30):
            limit = half[:2] - radius - WALL_GAP
            for _ in range(200):
                xy = rng.uniform(-limit, limit)
                lo, hi = np.array([*(xy - radius), 0.0]), np.array([*(xy + radius), top])
                clear = np.linalg.norm(np.maximum(np.abs(xy) - keep_out, 0.0)) >= radius
                if clear and _free(lo, hi, boxes):
                    boxes.append((lo, hi))
                    return xy, radius
            radius *= 0.9
        raise RuntimeError("room too small for its objects")

    for index in range(4):
        extent = np.array([rng.uniform(0.15, 0.4), rng.uniform(0.15, 0.4), 0.0])
        extent[2] = rng.uniform(0.15, 0.45 if index == 0 else 0.55)
        r = min(extent[0], extent[1], 0.3) * rng.uniform(0.7, 1.0)
        top = 2 * extent[2] + (2 * r if index == 0 else 0.0)
        footprint = float(np.hypot(extent[0], extent[1]))
        xy, radius = spot(footprint, top)
        extent[:2] *= radius / footprint
        yaw = rng.uniform(0.3, 1.2) if index == 1 else 0.0
        objects.append(Box(np.array([*xy, extent[2]]), extent, yaw, material(), f"box{index}"))
        if index == 0:
            r = min(r, extent[0], extent[1])
            sphere_centre = np.array([*xy, 2 * extent[2] + r])
            objects.append(Sphere(sphere_centre, r, material(), name="sphere_on_box0"))
    for index in range(2):
        height = rng.uniform(0.4, 1.6)
        xy, r = spot(rng.uniform(0.1, 0.3), height)
        objects.append(Cylinder(xy, r, 0.0, height, material(), name=f"cylinder{index}"))
    for index in range(2):
        radius = rng.uniform(0.15, 0.35)
        xy, r = spot(radius, 2 * radius)
        objects.append(Sphere(np.array([*xy, r]), r, material(), name=f"sphere{index}"))
    for index in range(2):
        extent = np.array([rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5), rng.uniform(0.15, 0.35)])
        axis, side = int(rng.integers(2)), int(rng.integers(2))
        extent[axis] = rng.uniform(0.06, 0.15)
        for _ in range(200):
            centre = rng.uniform(-half + extent + WALL_GAP, half - extent - WALL_GAP)
            centre[2] = rng.uniform(0.9 + extent[2], size[2] - 0.2 - extent[2])
            centre[axis] = (half[axis] - extent[axis]) * (1.0 if side else -1.0)
            lo, hi = centre - extent, centre + extent
            if _free(lo, hi, boxes):
                boxes.append((lo, hi))
                cabinet = Box(
                    centre, extent, 0.0, material(), f"wall_box{index}", (2 * axis + side,)
                )
                objects.append(cabinet)
                break
    return Scene(
        (room, *objects),
        np.array([-camera_half[0], -camera_half[1], 1.3]),
        np.array([camera_half[0], camera_half[1], 1.7]),
    )


SCENES: dict[str, Callable[[np.random.Generator], Scene]] = {"room": build_room}
"""Scene builders by name; each takes a seeded numpy Generator."""


def _scene_builder(name: str) -> Callable[[np.random.Generator], Scene]:
    if name not in SCENES:
        raise ValueError(
            f"unknown synthetic scene '{name}' (choose one of: {', '.join(sorted(SCENES))})"
        )
    return SCENES[name]


def build_scene(name: str, seed: int) -> Scene:
    """The scene ``name`` for ``seed`` (ValueError listing the choices for an unknown name)."""
    return _scene_builder(name)(np.random.default_rng([seed, 0]))


def look_at(position: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """(4, 4) camera-to-world pose at ``position`` looking at ``target``, OpenCV axes.

    The image x axis is horizontal (world z up) before rotating by ``roll`` (rad) about
    the viewing direction; a view straight up or down uses world x as the reference.
    """
    forward = np.asarray(target, dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-6:
        right = np.cross(forward, [1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    c, s = math.cos(roll), math.sin(roll)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([c * right + s * down, c * down - s * right, forward], axis=1)
    pose[:3, 3] = position
    return pose


def _sway(i: np.ndarray, period: float, rate: float, phase: float, order: int = 0) -> np.ndarray:
    """A sinusoid of ``period`` frames whose rate of change peaks at ``rate`` per frame
    (``order`` 0), or that rate of change itself (``order`` 1)."""
    angle = 2 * math.pi * i / period + phase
    if order:
        return rate * np.cos(angle)
    return rate * period / (2 * math.pi) * np.sin(angle)


def camera_trajectory(scene: Scene, config: SynthConfig) -> np.ndarray:
    """Smooth hand-held-like camera-to-world poses (N, 4, 4) float64 inside the camera box.

    The centre runs at ``step_translation`` (+-30 %, slowly varying) along a closed
    Lissajous-like loop filling the box. The view direction sweeps in yaw at
    ``step_rotation_deg`` per frame (+-30 %, slowly varying), sways in pitch around
    14-22 degrees down and rolls by a few degrees; a look-at builds each rotation.
    """
    rng = np.random.default_rng([config.seed, 1])
    phase = rng.uniform(0.0, 2 * math.pi, 8)
    s = np.linspace(0.0, 2 * math.pi, 8193) * rng.choice([-1.0, 1.0])
    unit_curve = np.stack(
        [
            0.75 * np.cos(s + phase[0]) + 0.25 * np.sin(2 * s + phase[1]),
            0.75 * np.sin(s + phase[0]) + 0.25 * np.cos(3 * s + phase[2]),
            np.sin(2 * s + phase[3]),
        ],
        axis=1,
    )
    curve = (scene.camera_lo + scene.camera_hi) / 2 + unit_curve * (
        scene.camera_hi - scene.camera_lo
    ) / 2
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    i = np.arange(config.frames, dtype=np.float64)
    speed = config.step_translation + _sway(i, 150, 0.3 * config.step_translation, phase[4], 1)
    arc = np.mod(rng.uniform(0.0, length[-1]) + np.cumsum(speed) - speed[0], length[-1])
    positions = np.stack([np.interp(arc, length, curve[:, k]) for k in range(3)], axis=1)

    step = math.radians(config.step_rotation_deg)
    spin = rng.choice([-1.0, 1.0])
    yaw = rng.uniform(0.0, 2 * math.pi) + spin * (step * i + _sway(i, 240, 0.3 * step, phase[5]))
    pitch = -math.radians(rng.uniform(14.0, 22.0)) + _sway(i, 300, 0.3 * step, phase[6])
    roll = _sway(i, 400, 0.1 * step, phase[7])
    forward = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], 1)
    return np.stack(
        [look_at(p, p + 2.0 * f, r) for p, f, r in zip(positions, forward, roll, strict=True)]
    )


def sensor_depth(view: RenderedView, rng: np.random.Generator, config: SynthConfig) -> np.ndarray:
    """Depth as a Kinect-like sensor would give it (see ``depth_noise``, ``missing_depth``).

    Returns:
        (H, W) float32 metres, 0 = missing.
    """
    exact = view.depth.astype(np.float64)
    depth = exact.copy()
    if config.depth_noise:
        a, b, z0 = KINECT_AXIAL_NOISE
        depth += rng.normal(size=depth.shape) * (a + b * (exact - z0) ** 2)
    if config.missing_depth:
        missing = (rng.random(depth.shape) < MISSING_FRACTION) | (
            view.cos_incidence < GRAZING_COSINE
        )
        padded = np.pad(exact, 1, mode="edge")
        for neighbour in (padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]):
            missing |= np.abs(neighbour - exact) > EDGE_JUMP * np.minimum(neighbour, exact)
        depth[missing] = 0.0
    depth[exact <= 0] = 0.0
    return np.maximum(depth, 0.0).astype(np.float32)


def generate_sequence(config: SynthConfig) -> Iterator[Frame]:
    """Yield the frames of the synthetic sequence (rendered lazily, one at a time)."""
    scene = build_scene(config.scene, config.seed)
    intrinsics = synthetic_intrinsics(config)
    for index, pose in enumerate(camera_trajectory(scene, config)):
        view = render_view(scene, intrinsics, pose)
        depth = view.depth
        if config.depth_noise or config.missing_depth:
            depth = sensor_depth(view, np.random.default_rng([config.seed, 2, index]), config)
        yield Frame(index, view.rgb, depth, intrinsics, pose.copy(), index / FPS)


def describe_scene(scene: Scene) -> list[dict]:
    """One JSON-ready line per primitive: name, type and its parameters (m, rad)."""
    lines = []
    for primitive in scene.primitives:
        fields = {"name": primitive.name, "type": type(primitive).__name__}
        for key in ("lo", "hi", "centre", "half", "radius", "yaw", "z0", "z1"):
            value = getattr(primitive, key, None)
            if value is not None:
                fields[key] = np.round(np.asarray(value, dtype=np.float64), 6).tolist()
        lines.append(fields)
    return lines


BOUND_MARGIN = 0.1
"""Margin (m) around the room box in the scene bound written to synth.json."""


def scene_bound(scene: Scene, margin: float = BOUND_MARGIN) -> list[list[float]]:
    """[[xmin, xmax], [ymin, ymax], [zmin, zmax]] of the room box grown by ``margin`` metres."""
    room = next(p for p in scene.primitives if isinstance(p, RoomBox))
    return [
        [float(lo) - margin, float(hi) + margin] for lo, hi in zip(room.lo, room.hi, strict=True)
    ]


def read_synthetic_bound(root: str | Path) -> list[list[float]]:
    """The scene bound recorded in ``root/synth.json`` by :func:`write_synthetic_sequence`."""
    path = Path(root) / "synth.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))["bound"]
    except FileNotFoundError:
        raise InputError(path, "not found (is this a folder written by `eslam synth`?)") from None
    except (KeyError, json.JSONDecodeError) as error:
        raise InputError(
            path, f"has no scene bound ({error})", "rewrite it with `eslam synth`"
        ) from None


def write_synthetic_sequence(
    out_dir: str | Path, config: SynthConfig, overwrite: bool = False
) -> Path:
    """Write the sequence of ``config`` to ``out_dir`` in the Replica layout.

    ``out_dir`` gets ``results/frame*.jpg``, ``results/depth*.png``, ``traj.txt``,
    ``cam_params.json``, the ground-truth ``mesh.ply`` and ``synth.json``. The folder
    is built beside ``out_dir`` and moved into place when complete.

    Raises:
        InputError: ``out_dir`` exists and is not empty (and ``overwrite`` is off).
    """
    out_dir = Path(out_dir)
    scene = build_scene(config.scene, config.seed)
    try:
        with atomic_directory(out_dir, overwrite=overwrite) as staging:
            write_mesh_ply(staging / "mesh.ply", scene_mesh(scene))
            write_replica_sequence(staging, generate_sequence(config), REPLICA_DEPTH_SCALE)
            info = {
                "config": asdict(config),
                "fps": FPS,
                "world": "metres, z up, floor at z = 0; poses camera-to-world, OpenCV axes",
                "mesh": "mesh.ply",
                "scene": describe_scene(scene),
                "bound": scene_bound(scene),
            }
            write_text(staging / "synth.json", json.dumps(info, indent=2) + "\n")
    except FileExistsError as error:
        raise InputError(
            out_dir, "already exists and is not empty", "choose a new folder"
        ) from error
    return out_dir
