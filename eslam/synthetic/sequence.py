"""Synthetic frames in memory: a lazy frame iterator and an in-memory RGBDSequence.

Frame i is ray cast (:func:`eslam.synthetic.render.render_view`) from pose i of
:func:`eslam.synthetic.trajectory.camera_trajectory`, with the sensor flaws of the
config applied (noise seeded by (seed, 2, i)). Everything is deterministic for a seed;
frame i does not depend on the number of frames, so a short sequence is a prefix of a
long one. Poses are camera-to-world, OpenCV camera axes.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from eslam.synthetic.config import FPS, SynthConfig, synthetic_intrinsics
from eslam.synthetic.primitives import Scene
from eslam.synthetic.render import render_view
from eslam.synthetic.scenes import build_scene
from eslam.synthetic.sensor import sensor_depth
from eslam.synthetic.trajectory import camera_trajectory
from eslam.types import Frame, Intrinsics


def _render(
    scene: Scene, config: SynthConfig, pose: np.ndarray, index: int, timestamp: float
) -> Frame:
    view = render_view(scene, synthetic_intrinsics(config), pose)
    depth = view.depth
    if config.depth_noise or config.missing_depth:
        depth = sensor_depth(view, np.random.default_rng([config.seed, 2, index]), config)
    reported = synthetic_intrinsics(config, reported=True)
    return Frame(index, view.rgb, depth, reported, pose.copy(), timestamp)


def generate_sequence(config: SynthConfig) -> Iterator[Frame]:
    """Yield the frames of the synthetic sequence (rendered lazily, one at a time).

    Frame i's timestamp is i / FPS seconds (what the TUM writer stamps).
    """
    scene = build_scene(config.scene, config.seed)
    for index, pose in enumerate(camera_trajectory(scene, config)):
        yield _render(scene, config, pose, index, index / FPS)


class SyntheticSequence:
    """The sequence of ``config`` rendered in memory, frame by frame on access.

    An :class:`~eslam.data.base.RGBDSequence` with the frames that
    ``write_synthetic_sequence(out, config)`` writes and ``ReplicaSequence(out)`` reads
    back: the same intrinsics, ground-truth poses and timestamps (the frame numbers, as
    the Replica layout has no time stamps), and the same images up to the files'
    rounding (depth PNG steps of 1 / 6553.5 m, JPEG colour). Tests use it to skip the
    disk round trip.

    Args:
        config: what to render.
        root: the name this sequence goes by in error messages (nothing is read there).
    """

    def __init__(self, config: SynthConfig, root: str | Path | None = None) -> None:
        self.config = config
        self.scene = build_scene(config.scene, config.seed)
        self.intrinsics: Intrinsics = synthetic_intrinsics(config, reported=True)
        self.root = Path(root or f"synthetic-{config.scene}-seed{config.seed}")
        self._poses = camera_trajectory(self.scene, config)

    def __len__(self) -> int:
        return len(self._poses)

    def __getitem__(self, index: int) -> Frame:
        if not 0 <= index < len(self):
            raise IndexError(f"frame {index} out of range for {len(self)} frames")
        return _render(self.scene, self.config, self._poses[index], index, float(index))

    def gt_poses(self) -> np.ndarray:
        """(N, 4, 4) float64 camera-to-world poses (exact: every frame has one)."""
        return self._poses.copy()

    def timestamps(self) -> np.ndarray:
        """(N,) float64 frame numbers 0, 1, 2, ... (as ReplicaSequence gives them)."""
        return np.arange(len(self), dtype=np.float64)
