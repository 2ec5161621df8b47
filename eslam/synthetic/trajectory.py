"""The synthetic camera path: smooth hand-held-like camera-to-world poses in a scene."""

from __future__ import annotations

import math

import numpy as np

from eslam.synthetic.config import SynthConfig
from eslam.synthetic.primitives import Scene


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


MAX_PITCH_SWAY_DEG = 25.0
"""Largest pitch swing about the mean downward tilt (14-22 degrees), so the camera never
looks straight down, where the look-at turns the image over (a 180-degree roll in one
frame). Reached only above about 1.7 degrees of yaw per frame."""

MAX_ROLL_SWAY_DEG = 10.0
"""Largest roll swing about the horizon. Reached only above about 1.6 degrees of yaw per
frame."""


def _rate_for(amplitude: float, period: float) -> float:
    """The peak rate of change per frame of a sinusoid of ``amplitude`` and ``period``."""
    return amplitude * 2 * math.pi / period


def camera_trajectory(scene: Scene, config: SynthConfig) -> np.ndarray:
    """The camera-to-world poses (N, 4, 4) float64 of ``config.trajectory``:
    :func:`sway_trajectory` or :func:`loop_trajectory`."""
    if config.trajectory == "loop":
        return loop_trajectory(scene, config)
    return sway_trajectory(scene, config)


LOOP_PITCH_DEG = 18.0
"""Downward tilt of the loop's camera: it sees the walls and some floor."""


def loop_lap_frames(scene: Scene, config: SynthConfig) -> int:
    """Frames of one lap of :func:`loop_trajectory`: the ellipse's perimeter (Ramanujan's
    approximation) over ``step_translation``."""
    a, b = 0.9 * (scene.camera_hi[:2] - scene.camera_lo[:2]) / 2
    h = ((a - b) / (a + b)) ** 2
    perimeter = math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))
    return max(8, round(perimeter / config.step_translation))


def loop_trajectory(scene: Scene, config: SynthConfig) -> np.ndarray:
    """A lap around the room that comes back to its start, looking outwards.

    The centre runs along an ellipse filling 90 % of the camera box's floor plan, at
    ``step_translation`` per frame (one lap: :func:`loop_lap_frames`; frames past it go
    round again, so a sequence longer than a lap returns to the views it began with),
    at the box's mid height with a slow +-5 cm bob; the camera looks away from the
    ellipse's centre, :data:`LOOP_PITCH_DEG` down, so its yaw turns a full circle per
    lap. Frame i does not depend on ``config.frames``.
    """
    rng = np.random.default_rng([config.seed, 3])
    lap = loop_lap_frames(scene, config)
    centre = (scene.camera_lo + scene.camera_hi) / 2
    a, b = 0.9 * (scene.camera_hi[:2] - scene.camera_lo[:2]) / 2
    i = np.arange(config.frames, dtype=np.float64)
    angle = rng.uniform(0.0, 2 * math.pi) + rng.choice([-1.0, 1.0]) * 2 * math.pi * i / lap
    height = centre[2] + 0.05 * np.sin(2 * math.pi * i / 97.0)
    positions = np.stack([centre[0] + a * np.cos(angle), centre[1] + b * np.sin(angle), height], 1)
    pitch = -math.radians(LOOP_PITCH_DEG)
    forward = np.stack(
        [
            math.cos(pitch) * np.cos(angle),
            math.cos(pitch) * np.sin(angle),
            np.full_like(i, math.sin(pitch)),
        ],
        axis=1,
    )
    return np.stack([look_at(p, p + 2.0 * f) for p, f in zip(positions, forward, strict=True)])


def sway_trajectory(scene: Scene, config: SynthConfig) -> np.ndarray:
    """Smooth hand-held-like camera-to-world poses (N, 4, 4) float64 inside the camera box.

    The centre runs at ``step_translation`` (+-30 %, slowly varying) along a closed
    Lissajous-like loop filling the box. The view direction sweeps in yaw at
    ``step_rotation_deg`` per frame (+-30 %, slowly varying), sways in pitch around
    14-22 degrees down and rolls by a few degrees (their swings grow with the step, up
    to :data:`MAX_PITCH_SWAY_DEG` and :data:`MAX_ROLL_SWAY_DEG`, so a fast yaw stays a
    yaw); a look-at builds each rotation.
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
    pitch_rate = min(0.3 * step, _rate_for(math.radians(MAX_PITCH_SWAY_DEG), 300))
    roll_rate = min(0.1 * step, _rate_for(math.radians(MAX_ROLL_SWAY_DEG), 400))
    pitch = -math.radians(rng.uniform(14.0, 22.0)) + _sway(i, 300, pitch_rate, phase[6])
    roll = _sway(i, 400, roll_rate, phase[7])
    forward = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], 1)
    return np.stack(
        [look_at(p, p + 2.0 * f, r) for p, f, r in zip(positions, forward, roll, strict=True)]
    )
