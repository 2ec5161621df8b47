"""Seconds per frame of the SDF tracker on a finished run's map, per point pyramid.

The map of RUN (its map.pt and config.yaml) is frozen and each frame of the run's
sequence (1..N, or from ``--first``) is tracked by the SDF tracker alone
(:class:`eslam.slam.tracking.sdf.SdfTracker`, the run's ``tracking.sdf`` settings with
``levels`` replaced) from the previous frame's reference pose, i.e. the error a tracker
without a motion model starts from. The reference is the ground truth, or with
``--poses estimate`` the run's own trajectory.txt: the frame its map was built in, which
on real data drifts from the ground truth by the run's ATE (a centimetre or more on
7-Scenes) and so puts the ground-truth poses' points off the map's surfaces. Per point
pyramid it reports the median and maximum wall time per frame, the mean translation
error against the reference, the mean iterations, and the smallest eigenvalue of the
normalised information at the reference poses (minimum and median over the frames;
:func:`eslam.slam.tracking.sdf_system.normalised_information`: near 0 means a degenerate view,
e.g. one plane; ``tracking.sdf.degeneracy`` holds the directions below its threshold).
With ``--colour-weights`` each pyramid is measured once per weight of the colour term
(``tracking.sdf.colour_weight``), and the table also gives the mean rotation error.

    python benchmarks/sdf_tracking.py runs/room0 --levels 1000,4000 500,2000 2000
    python benchmarks/sdf_tracking.py runs/demo --frames 20 --colour-weights 0 0.1 0.2
    python benchmarks/sdf_tracking.py runs/kitchen --poses estimate --frames 399 --levels 2000,8000

Prints a markdown table and, unless ``--no-append``, appends it to docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import itertools

from _machine import DEFAULT_DOCS, command_line, load_average, machine_lines, publish

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.field.scene_field import SceneField
from eslam.geometry.pose import pose_distance
from eslam.io.checkpoint import load_checkpoint
from eslam.io.trajectory import read_trajectory
from eslam.render.rays import camera_directions
from eslam.slam.tracking.sdf import SdfTracker, sdf_points
from eslam.slam.tracking.sdf_system import linearise, normalised_information
from eslam.slam.views import make_view


@dataclasses.dataclass(frozen=True)
class Row:
    levels: tuple[int, ...]
    colour_weight: float
    median_s: float
    max_s: float
    error_mm: float
    error_deg: float
    iterations: float
    information_min: float
    information_median: float


REFERENCE = {"truth": "ground-truth pose", "estimate": "pose in the run's trajectory.txt"}


def reference_poses(run: Path, sequence, which: str) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses tracking starts from and is scored against:
    the sequence's ground truth (``truth``) or the run's trajectory.txt (``estimate``)."""
    if which == "estimate":
        return read_trajectory(run)[1]
    poses = sequence.gt_poses()
    if poses is None:
        raise SystemExit(f"{run}: the sequence has no ground truth; use --poses estimate")
    return poses


def tracked_range(args: argparse.Namespace, frame_count: int) -> range:
    """Frames tracked: ``--first`` up to ``--frames`` of them, within the ``frame_count``
    frames that have a reference pose."""
    tracked = range(args.first, min(args.first + args.frames, frame_count))
    if args.first < 1 or not tracked:
        raise SystemExit(f"{args.run}: no frames to track from --first {args.first}")
    return tracked


def measure(args: argparse.Namespace) -> tuple[list[Row], range]:
    """One row per point pyramid and colour weight, and the frames tracked."""
    config = load_config(args.run / "config.yaml")
    saved = load_checkpoint(args.run / "map.pt")
    field = SceneField.from_state(config.field, saved["field"])
    field.requires_grad_(False)
    sequence = open_sequence(config.data)
    directions = camera_directions(sequence.intrinsics)
    reference = reference_poses(args.run, sequence, args.poses)
    tracked = tracked_range(args, min(len(reference), len(sequence)))
    indices = range(tracked.start - 1, tracked.stop)
    missing = [i for i in indices if not np.isfinite(reference[i]).all()]
    if missing:
        raise SystemExit(f"{args.run}: frame {missing[0]} has no {REFERENCE[args.poses]}")
    frames = [sequence[i] for i in indices]
    rows = []
    for levels, weight in itertools.product(args.levels, args.colour_weights):
        settings = dataclasses.replace(config.tracking.sdf, levels=levels, colour_weight=weight)
        tracker = SdfTracker(settings)
        seconds, errors, turns, iterations, smallest = [], [], [], [], []
        for previous, frame in itertools.pairwise(frames):
            view = make_view(
                torch.from_numpy(frame.rgb).float() / 255.0,
                torch.from_numpy(frame.depth),
                directions,
                config.tracking.border,
            )
            truth = torch.from_numpy(reference[frame.index]).float()
            points, pixels = sdf_points(view, max(levels), torch.Generator().manual_seed(0))
            colours = view.rgb[pixels] if weight > 0 else None
            at_truth = linearise(field, points, truth, tracker.config, colours)
            smallest.append(float(normalised_information(at_truth)[0][0]))
            start = torch.from_numpy(reference[previous.index]).float()
            begin = time.perf_counter()
            result = tracker.track(field, view, start, torch.Generator().manual_seed(frame.index))
            seconds.append(time.perf_counter() - begin)
            translation, rotation = pose_distance(result.pose, truth)
            errors.append(1000.0 * float(translation))
            turns.append(math.degrees(float(rotation)))
            assert result.quality is not None
            iterations.append(result.quality.iterations)
        rows.append(
            Row(
                levels,
                weight,
                statistics.median(seconds),
                max(seconds),
                statistics.mean(errors),
                statistics.mean(turns),
                statistics.mean(iterations),
                min(smallest),
                statistics.median(smallest),
            )
        )
        print(rows[-1], flush=True)
    return rows, tracked


def table(rows: list[Row]) -> str:
    lines = [
        "| levels (points) | colour weight | median (s/frame) | max (s/frame) "
        "| mean error (mm) | mean error (deg) | iterations "
        "| smallest information (min / median) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {', '.join(map(str, row.levels))} | {row.colour_weight:g} "
            f"| {row.median_s:.3f} | {row.max_s:.3f} "
            f"| {row.error_mm:.2f} | {row.error_deg:.3f} | {row.iterations:.1f} "
            f"| {row.information_min:.3f} / {row.information_median:.3f} |"
        )
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", type=Path, help="a finished run folder (map.pt, config.yaml)")
    parser.add_argument(
        "--levels", nargs="+", default=["1000,4000"], help="point pyramids, e.g. 500,2000"
    )
    parser.add_argument(
        "--colour-weights",
        nargs="+",
        type=float,
        default=[0.0],
        help="tracking.sdf.colour_weight values, each measured (metres per unit colour)",
    )
    parser.add_argument("--frames", type=int, default=19, help="frames tracked")
    parser.add_argument("--first", type=int, default=1, help="the first frame tracked")
    parser.add_argument(
        "--poses",
        choices=("truth", "estimate"),
        default="truth",
        help="reference poses: the ground truth, or the run's own trajectory.txt",
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("--note", default="")
    args = parser.parse_args(argv)
    args.levels = [tuple(int(n) for n in text.split(",")) for text in args.levels]
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    command = command_line("benchmarks/sdf_tracking.py", argv)
    load_start = load_average()
    rows, tracked = measure(args)
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## sdf_tracking, {now}, cpu",
        "",
        *machine_lines(torch.device("cpu"), (load_start, load_average())),
        f"- command: `{command}`",
        f"- workload: the map of `{args.run}`, frames {tracked.start}-{tracked[-1]}"
        f" of its sequence, each tracked from the previous frame's {REFERENCE[args.poses]}",
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    publish("\n".join([*lines, "", table(rows)]), args.docs, args.no_append)


if __name__ == "__main__":
    main()
