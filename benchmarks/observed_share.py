"""How much of each tracked frame lies in space the keyframes observed?

``tracking.observed_only`` (docs/tracking.md) tracks a frame only on the pixels whose
depth point, at the motion model's guess, lies in space some keyframe observed
(:func:`eslam.slam.tracking.observed_view.observed_pixels`). This script measures the share of
a frame's trackable pixels (valid depth, outside ``tracking.border``) that test passes,
at the reference poses, with every ``mapping.every``-th earlier frame as a keyframe
(the run loop's keyframes when no frame fails): the most the option can change. No
SLAM runs; it reads the sequence only.

    python benchmarks/observed_share.py --config configs/sevenscenes/redkitchen_cpu.yaml \\
        --data ../shared/data/7scenes-redkitchen --frames 400 --segment 50
"""

from __future__ import annotations

import argparse
import datetime
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import DEFAULT_DOCS, command_line, publish

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.mesh.observed import ObservedViews
from eslam.render.rays import camera_directions
from eslam.slam.tracking.observed_view import observed_pixels
from eslam.slam.views import make_view, sampleable_mask


def observed_shares(
    config_path: Path, data: Path, frames: int, overrides: tuple[str, ...] = ()
) -> np.ndarray:
    """(frames - 1,) share of frame k's trackable pixels in observed space, k = 1..frames-1
    (module doc); ``overrides`` are ``key=value`` settings on the config."""
    config = load_config(config_path, [f"data.path={data}", *overrides])
    sequence = open_sequence(config.data)
    if len(sequence) < frames:
        raise SystemExit(f"{data} holds {len(sequence)} frames, fewer than --frames {frames}")
    loaded = [sequence[k] for k in range(frames)]
    if any(frame.pose_gt is None for frame in loaded):
        raise SystemExit(f"{data}: a frame of the first {frames} has no reference pose")
    camera = loaded[0].intrinsics
    directions = camera_directions(camera)
    poses = torch.from_numpy(np.stack([frame.pose_gt for frame in loaded])).float()
    depths = torch.from_numpy(np.stack([frame.depth for frame in loaded]))
    shares = []
    for k in range(1, frames):
        keyframes = list(range(0, k, config.mapping.every))
        views = ObservedViews(poses[keyframes], depths[keyframes], camera, config.field.truncation)
        rgb = torch.zeros(camera.height, camera.width, 3)
        view = make_view(rgb, depths[k], directions, config.tracking.border)
        trackable = sampleable_mask(view)
        kept = trackable & observed_pixels(view, poses[k], views)
        shares.append(float(kept.sum()) / max(1, int(trackable.sum())))
    return np.asarray(shares)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", type=Path, required=True)
    parser.add_argument("--data", type=Path, required=True, help="the sequence folder")
    parser.add_argument("--frames", type=int, default=400)
    parser.add_argument("--segment", type=int, default=50, help="frames per table row")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("overrides", nargs="*", help="key=value settings on the config")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.frames < 2 or args.segment < 1:
        raise SystemExit("--frames must be at least 2 and --segment at least 1")
    torch.set_num_threads(args.threads)
    shares = observed_shares(args.config, args.data, args.frames, tuple(args.overrides))
    rows = []
    for start in range(1, args.frames, args.segment):
        part = shares[start - 1 : start - 1 + args.segment]
        end = start + len(part) - 1
        rows.append(
            f"| {start}-{end} | {100 * np.median(part):.1f} | {100 * part.min():.1f} "
            f"| {int((part < 0.95).sum())} |"
        )
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    section = "\n".join(
        [
            f"## observed_share, {now}",
            "",
            f"- command: `{command_line('benchmarks/observed_share.py', argv)}`",
            f"- frames 1-{args.frames - 1} at their reference poses; keyframes every "
            "mapping.every-th earlier frame; share of the trackable pixels in observed "
            f"space: median {100 * np.median(shares):.1f} %, lowest {100 * shares.min():.1f} %",
            "",
            "| frames | share observed, median (%) | lowest (%) | frames under 95 % |",
            "|---|---:|---:|---:|",
            *rows,
            "",
        ]
    )
    publish(section, args.docs, args.no_append)


if __name__ == "__main__":
    main()
