"""What a synthetic sequence is made of: :class:`SynthConfig` and the camera it implies."""

from __future__ import annotations

import math
from dataclasses import dataclass

from eslam.synthetic.scenes import scene_builder
from eslam.types import Intrinsics

FPS = 30.0
"""Frame rate of the synthetic camera: timestamp = index / FPS seconds."""


TRAJECTORIES = ("sway", "loop")
"""The camera paths :func:`eslam.synthetic.trajectory.camera_trajectory` draws."""


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
    """Scene builder, a key of :data:`eslam.synthetic.scenes.SCENES`."""
    hfov_deg: float = 65.0
    """Horizontal field of view, degrees (fx = fy; square pixels)."""
    step_translation: float = 0.01
    """Mean camera translation per frame, m (it varies by +-30 % along the way)."""
    step_rotation_deg: float = 0.5
    """Typical camera rotation per frame, degrees (yaw sweep plus pitch and roll sway)."""
    trajectory: str = "sway"
    """The camera path: ``sway`` (a hand-held-like Lissajous loop with a yaw sweep) or
    ``loop`` (laps around the room looking outwards: a sequence longer than a lap
    returns to the views it began with; :func:`eslam.synthetic.trajectory.loop_trajectory`)."""
    focal_error: float = 0.0
    """Relative error of the focal length the sequence reports: frames are rendered with
    the true focal length but carry fx, fy x (1 + focal_error), so odometry drifts (it
    turns too little or too much at every rotation) while the ground truth stays exact."""
    depth_noise: bool = False
    """Add Kinect-like axial noise, sigma(z) from sensor.KINECT_AXIAL_NOISE (seeded)."""
    missing_depth: bool = False
    """Drop sensor.MISSING_FRACTION of the pixels at random, and grazing and edge pixels."""

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
        if self.trajectory not in TRAJECTORIES:
            raise ValueError(
                f"trajectory must be one of {', '.join(TRAJECTORIES)}, got '{self.trajectory}'"
            )
        if not -0.5 < self.focal_error < 0.5:
            raise ValueError(f"focal_error must be in (-0.5, 0.5), got {self.focal_error}")
        scene_builder(self.scene)


def synthetic_intrinsics(config: SynthConfig, reported: bool = False) -> Intrinsics:
    """Pinhole intrinsics of the synthetic camera: fx = fy from hfov, centred principal
    point; ``reported``: those the frames carry (the focal length x (1 + focal_error))."""
    focal = 0.5 * config.width / math.tan(math.radians(config.hfov_deg) / 2.0)
    if reported:
        focal *= 1.0 + config.focal_error
    return Intrinsics(
        config.width, config.height, focal, focal, (config.width - 1) / 2, (config.height - 1) / 2
    )
