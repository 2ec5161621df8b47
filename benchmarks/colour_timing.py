"""Is a registered RGB-D sequence's colour where its depth is, in space and in time? (TUM)

TUM's depth images are registered to the colour camera by the sensor, but the two
streams are not synchronised: a frame's colour and depth images are taken up to 20 ms
apart, and a moving camera shifts the colour by its motion over that gap. Scored by
edge alignment (:func:`eslam.data.registration.edge_view`: the colour gradient averaged
over the depth image's discontinuities, higher = better aligned), per frame:

- ``as read``: the colour pixel that shares the depth pixel's coordinates;
- ``best shift``: the colour moved by one (dx, dy) for every frame, the best of a grid
  of ``--shift-px`` steps (a static misregistration shows as a shift away from 0);
- ``moved``: each depth pixel's 3-D point seen from the colour camera's pose at the
  colour image's time (ground truth at both stamps, ``data.stamp`` colour and depth):
  u = K (R p + t) with (R, t) = T_colour^-1 T_depth. If the time gap matters this
  scores above ``as read``, most where the gap and the motion are large.

No SLAM runs here; it reads the sequence and its ground truth only.

    python benchmarks/colour_timing.py --config tum/tum_cpu \\
        --data .../rgbd_dataset_freiburg1_xyz [--every 5]
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import command_line, cpu_model

from eslam.config import ESLAMConfig, load_config
from eslam.data import open_sequence
from eslam.data.registration import edge_score, edge_view
from eslam.errors import ESLAMError, InputError
from eslam.slam.mapping.colour_motion import moved_pixels

GAP_BINS_MS = (0.0, 5.0, 10.0, 1e9)
"""|colour time - depth time| bins of the table's rows, ms."""


@dataclass(frozen=True)
class FrameScore:
    """One frame's edge-alignment scores (module doc): colour time - depth time (ms),
    the colour moved by the camera's motion, and the colour shifted by each of the
    grid's (dx, dy) (``shifts``' order)."""

    gap_ms: float
    moved: float
    shifted: np.ndarray


def measure(
    config: ESLAMConfig, data: Path, every: int, jump_m: float, shifts: list[tuple[float, float]]
) -> list[FrameScore]:
    """Every ``every``-th frame's :class:`FrameScore` (``config``'s reader, ground truth
    needed). Raises ESLAMError for a sequence that cannot be read."""
    by_colour = open_sequence(replace(config.data, path=str(data), stamp="colour"))
    by_depth = open_sequence(replace(config.data, path=str(data), stamp="depth"))
    gt_colour, gt_depth = by_colour.gt_poses(), by_depth.gt_poses()
    if gt_colour is None or gt_depth is None:
        raise InputError(data / "groundtruth.txt", "missing", "the check needs ground truth")
    # both stamps' poses in the depth-stamped reader's world: T_c^-1 T_d
    world = np.linalg.inv(by_depth.mocap_from_world) @ by_colour.mocap_from_world
    gaps_ms = 1e3 * (by_colour.timestamps() - by_depth.timestamps())
    scores = []
    for index in range(0, len(by_depth), every):
        frame = by_depth[index]
        view = edge_view(frame.rgb, frame.depth, jump_m)
        v, u = np.mgrid[0 : frame.depth.shape[0], 0 : frame.depth.shape[1]].astype(np.float64)
        shifted = np.array([edge_score(view, u + dx, v + dy) for dx, dy in shifts])
        colour_from_depth = np.linalg.inv(world @ gt_colour[index]) @ gt_depth[index]
        motion = torch.from_numpy(colour_from_depth)
        u_m, v_m, _ = moved_pixels(frame.depth, by_depth.intrinsics, motion)
        scores.append(FrameScore(float(gaps_ms[index]), edge_score(view, u_m, v_m), shifted))
    return scores


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="tum/tum_cpu")
    parser.add_argument("--data", type=Path, required=True, help="a TUM RGB-D sequence folder")
    parser.add_argument("--every", type=int, default=5, help="use every k-th frame (5)")
    parser.add_argument("--jump-mm", type=float, default=25.0, help="depth edge threshold")
    parser.add_argument("--shift-px", type=float, default=0.5, help="shift grid step (px)")
    parser.add_argument("--shift-max", type=float, default=2.0, help="largest shift (px)")
    args = parser.parse_args(argv)
    steps = np.arange(-args.shift_max, args.shift_max + 1e-9, args.shift_px)
    shifts = [(float(dx), float(dy)) for dx in steps for dy in steps]
    try:
        scores = measure(
            load_config(args.config), args.data, args.every, args.jump_mm / 1e3, shifts
        )
    except ESLAMError as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")
    print(f"- command: `{command_line('benchmarks/colour_timing.py', argv)}`")
    print(f"- {len(scores)} frames (every {args.every}th), {cpu_model()}")
    zero = shifts.index((0.0, 0.0))
    totals = np.mean([score.shifted for score in scores], axis=0)
    best = int(np.argmax(totals))
    print(
        f"- best single shift over all frames: dx {shifts[best][0]:+.1f}, dy "
        f"{shifts[best][1]:+.1f} px (score {totals[best]:.4f}; as read {totals[zero]:.4f})"
    )
    print()
    print("| colour - depth time | frames | as read | moved by the motion | moved better in |")
    print("|---|---:|---:|---:|---:|")
    for low, high in itertools.pairwise(GAP_BINS_MS):
        chosen = [score for score in scores if low <= abs(score.gap_ms) < high]
        if not chosen:
            continue
        moved = np.array([score.moved for score in chosen])
        read = np.array([score.shifted[zero] for score in chosen])
        label = f">= {low:g} ms" if high > 1e8 else f"{low:g}-{high:g} ms"
        print(
            f"| {label} | {len(chosen)} | {read.mean():.4f} | {moved.mean():.4f} | "
            f"{int((moved > read).sum())} of {len(chosen)} |"
        )


if __name__ == "__main__":
    main()
