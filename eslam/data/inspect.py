"""Read a whole sequence once and summarise it: the check a user runs before a long run."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.data.base import RGBDSequence, iterate_frames
from eslam.data.depth_units import DepthCheck, sequence_depth_file, sequence_depth_scale
from eslam.errors import InputError
from eslam.types import Intrinsics


@dataclass(frozen=True)
class SequenceSummary:
    """What ``inspect_sequence`` found.

    Attributes:
        root: the sequence folder.
        frames: number of frames (all were read and checked).
        intrinsics: the camera.
        depth_min_m / depth_median_m / depth_max_m: over valid depth of all frames, metres.
        invalid_depth_fraction: share of pixels without depth, over all frames.
        has_ground_truth: whether every frame has a ground-truth pose.
        path_length_m: length of the ground-truth camera path (0 without ground truth).
        depth_problem: the first frame whose depth is not plausibly metres (the error a
            run would stop with), or None; ``implausible_frames`` counts them all.
        implausible_frames: frames failing the run's depth-unit check.
    """

    root: Path
    frames: int
    intrinsics: Intrinsics
    depth_min_m: float
    depth_median_m: float
    depth_max_m: float
    invalid_depth_fraction: float
    has_ground_truth: bool
    path_length_m: float
    depth_problem: InputError | None = None
    implausible_frames: int = 0

    def to_text(self) -> str:
        """A few human-readable lines."""
        k = self.intrinsics
        lines = [
            f"sequence   {self.root}",
            f"frames     {self.frames}",
            f"camera     {k.width}x{k.height}  fx {k.fx:g}  fy {k.fy:g}  cx {k.cx:g}  cy {k.cy:g}",
            f"depth      {self.depth_min_m:.3f} / {self.depth_median_m:.3f} / "
            f"{self.depth_max_m:.3f} m (min / median / max), "
            f"{100 * self.invalid_depth_fraction:.1f} % invalid",
        ]
        if self.has_ground_truth:
            lines.append(f"poses      ground truth, path length {self.path_length_m:.3f} m")
        else:
            lines.append("poses      no ground truth")
        if self.depth_problem is None:
            lines.append("units      depth plausibly in metres on every frame")
        else:
            lines.append(
                f"units      depth NOT in metres on {self.implausible_frames} of {self.frames} "
                "frames: a run refuses this input (the first below)"
            )
        return "\n".join(lines)


def inspect_sequence(
    sequence: RGBDSequence,
    depth_samples_per_frame: int = 2000,
    bound: list[list[float]] | None = None,
) -> SequenceSummary:
    """Read every frame of ``sequence`` (raising its reader's InputError on bad input).

    Depth statistics use an evenly strided subset of each frame's valid pixels
    (``depth_samples_per_frame``) so memory stays small on long sequences. Every frame
    also gets the run's depth-unit check (with ``bound``, a ``scene.bound``, if given),
    so inspect flags the input a run would refuse.
    """
    check = DepthCheck.for_run(sequence_depth_scale(sequence), bound)
    problem: InputError | None = None
    implausible = 0
    samples: list[np.ndarray] = []
    invalid = 0
    pixels = 0
    count = 0
    for frame in iterate_frames(sequence):
        valid = frame.valid_depth
        invalid += int(valid.size - valid.sum())
        pixels += valid.size
        depth = frame.depth[valid]
        if depth.size:
            step = max(1, depth.size // depth_samples_per_frame)
            samples.append(depth[::step])
        where = sequence_depth_file(sequence, count) or sequence.root
        found = check.problem(frame.depth, where, f"frame {count}")
        if found is not None:
            implausible += 1
            problem = problem or found
        count += 1
    depth_all = np.concatenate(samples) if samples else np.zeros(1, dtype=np.float32)
    poses = sequence.gt_poses()
    path_length = 0.0
    if poses is not None and len(poses) > 1:
        # frames without usable ground truth (NaN rows) are left out of the path
        positions = poses[np.isfinite(poses).all(axis=(1, 2)), :3, 3]
        path_length = float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())
    return SequenceSummary(
        root=sequence.root,
        frames=count,
        intrinsics=sequence.intrinsics,
        depth_min_m=float(depth_all.min()),
        depth_median_m=float(np.median(depth_all)),
        depth_max_m=float(depth_all.max()),
        invalid_depth_fraction=invalid / max(pixels, 1),
        has_ground_truth=poses is not None and bool(np.isfinite(poses).all(axis=(1, 2)).any()),
        path_length_m=path_length,
        depth_problem=problem,
        implausible_frames=implausible,
    )
