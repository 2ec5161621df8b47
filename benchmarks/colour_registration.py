"""Where is the colour camera of an unregistered RGB-D sequence? (7-Scenes)

Fits the colour camera of :mod:`eslam.data.registration` (one focal length fx = fy,
the principal point's row cy, the centre's x offset from the depth camera; cx fixed at
the image centre) by edge alignment: the registered colour image's gradient magnitude
is averaged over the depth image's discontinuities (depth jumps of more than
``--jump-mm`` between neighbours, away from invalid pixels). Texture and geometry
edges coincide where registration is right, so the score is highest there. A
coordinate search refines each parameter in turn on a shrinking grid.

It prints the score of the raw colour (the depth camera's K for both), of the
published-style guess and of the fit, and appends the table to docs/benchmarks.md.
No SLAM runs here; it reads the sequence only.

    python benchmarks/colour_registration.py --data ../shared/data/7scenes-redkitchen
"""

from __future__ import annotations

import argparse
import datetime
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import DEFAULT_DOCS, command_line, publish

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.data.registration import (
    ColourCamera,
    EdgeView,
    alignment_score,
    colour_pixel_of_depth_pixel,
    edge_view,
)
from eslam.data.sevenscenes import SEVENSCENES_COLOUR_CAMERA
from eslam.types import Intrinsics


def fit(
    frames: list[EdgeView],
    intrinsics: Intrinsics,
    start: ColourCamera,
    rounds: int,
) -> ColourCamera:
    """Coordinate search over (focal, cy, centre x) from ``start``; steps halve each round."""
    steps = {"focal": 10.0, "cy": 4.0, "baseline": 0.01}
    best = start
    best_score = alignment_score(frames, intrinsics, best)
    for _ in range(rounds):
        for name, step in steps.items():
            for delta in (-2 * step, -step, step, 2 * step):
                if name == "focal":
                    trial = replace(best, fx=best.fx + delta, fy=best.fy + delta)
                elif name == "cy":
                    trial = replace(best, cy=best.cy + delta)
                else:
                    x, y, z = best.centre
                    trial = replace(best, centre=(x + delta, y, z))
                score = alignment_score(frames, intrinsics, trial)
                if score > best_score:
                    best, best_score = trial, score
        steps = {name: step / 2 for name, step in steps.items()}
    return best


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="configs/sevenscenes/redkitchen.yaml")
    parser.add_argument("--data", type=Path, required=True, help="a 7-Scenes recording folder")
    parser.add_argument("--every", type=int, default=50, help="use every k-th frame (50)")
    parser.add_argument("--jump-mm", type=float, default=25.0, help="depth edge threshold")
    parser.add_argument("--rounds", type=int, default=4, help="coordinate-search rounds")
    parser.add_argument("--no-append", action="store_true", help="print only")
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    args = parser.parse_args(argv)
    config = load_config(args.config, ["data.register_colour=false"])
    sequence = open_sequence(replace(config.data, path=str(args.data)))
    intrinsics = sequence.intrinsics
    frames = []
    for index in range(0, len(sequence), args.every):
        frame = sequence[index]
        frames.append(edge_view(frame.rgb, frame.depth, args.jump_mm / 1e3))
    raw = ColourCamera.of_depth_camera(intrinsics)
    rows = [
        ("raw colour (depth camera's K for both)", raw),
        ("eslam's 7-Scenes colour camera", SEVENSCENES_COLOUR_CAMERA),
    ]
    fitted = fit(frames, intrinsics, SEVENSCENES_COLOUR_CAMERA, args.rounds)
    rows.append(("fit from eslam's", fitted))
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## colour_registration, {now}",
        "",
        f"- command: `{command_line('benchmarks/colour_registration.py', argv)}`",
        f"- data: {args.data} ({len(frames)} frames, every {args.every}th), depth edges "
        f"over {args.jump_mm:g} mm; score = mean colour gradient on depth edges (higher "
        "is better aligned)",
        "",
        "| colour camera | fx = fy | cy | centre x (cm) | score |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, camera in rows:
        score = alignment_score(frames, intrinsics, camera)
        lines.append(
            f"| {label} | {camera.fx:.1f} | {camera.cy:.1f} | "
            f"{100 * camera.centre[0]:.2f} | {score:.4f} |"
        )
    shifts = []
    for view in frames:
        u_c, v_c = colour_pixel_of_depth_pixel(view.depth, intrinsics, SEVENSCENES_COLOUR_CAMERA)
        v, u = np.mgrid[0 : view.depth.shape[0], 0 : view.depth.shape[1]]
        shifts.append(np.hypot(u_c - u, v_c - v)[view.depth > 0])
    shift = np.concatenate(shifts)
    lines += [
        "",
        f"- where eslam's colour camera finds the colour of a depth pixel, against the raw "
        f"reading (same pixel): median {np.median(shift):.1f} px, largest {shift.max():.1f} px "
        "(pixels with depth)",
    ]
    publish("\n".join(lines) + "\n", args.docs, args.no_append)


if __name__ == "__main__":
    main()
