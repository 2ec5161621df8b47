"""The starting pose from features coarse to fine (``tracking.start_coarse``) against
matching all with all: time, how often the coarse step gives a start, and how far each
start lies from the ground truth.

For frame pairs ``--gaps`` apart (every ``--every``-th frame of the sequence as the
earlier one), the later frame's starting pose from its ORB features matched to the
earlier frame's, the earlier one at its ground-truth pose
(:func:`eslam.slam.places.index.pose_from_matches`, as the tracking front end calls
it): all with all (``start_coarse`` 0) and coarse to fine from each of ``--coarse``
features. Per gap and setting: the time per start (matching, RANSAC, the fallback to
all with all where the coarse step gives no pose), the share of pairs whose start came
coarse to fine, the matches that agreed (median) and the start's error against the
later frame's ground truth (median and largest, mm and degrees). Per gap also how far
the features that agreed with the start of all with all moved in the image (median,
99th percentile, largest, pixels).

    python benchmarks/coarse_start.py --config tum/tum_cpu --data PATH \\
        [--gaps 1,10,30] [--coarse 300,500,1000] [--every 20] [--threads 1]

Prints markdown tables (docs take them by hand) with the machine.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch
from _machine import cpu_model

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.errors import ConfigError, InputError
from eslam.geometry.pose import pose_distance
from eslam.slam.places.features import Features, mutual_matches, opencv, orb_features
from eslam.slam.places.index import coarse_to_fine, pose_from_matches


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", required=True, help="a config name or file")
    parser.add_argument("--data", type=Path, required=True, help="the sequence")
    parser.add_argument("--gaps", default="1,10,30", help="frames between the two of a pair")
    parser.add_argument("--coarse", default="300,500,1000", help="coarse feature counts")
    parser.add_argument("--every", type=int, default=20, help="a pair from every k-th frame")
    parser.add_argument("--threads", type=int, default=1, help="torch and OpenCV threads")
    args = parser.parse_args(argv)
    try:
        args.gaps = [int(v) for v in args.gaps.split(",")]
        args.coarse = [int(v) for v in args.coarse.split(",")]
    except ValueError:
        parser.error("--gaps and --coarse take comma-separated integers, e.g. 1,10,30")
    if min(args.gaps + args.coarse) < 1 or args.every < 1 or args.threads < 1:
        parser.error("--gaps, --coarse, --every and --threads must be >= 1")
    return args


def displacement_px(query: Features, reference: Features, pose: np.ndarray) -> np.ndarray:
    """Pixels moved by the matches of all features that agree with the start ``pose``
    (within 3 cm, the reference at the identity)."""
    pairs = mutual_matches(query.descriptors, reference.descriptors)
    camera, points = query.points[pairs[:, 0]], reference.points[pairs[:, 1]]
    moved = camera @ pose[:3, :3].T + pose[:3, 3]
    agree = np.linalg.norm(moved - points, axis=1) < 0.03  # NaN depth: False
    return np.linalg.norm(query.pixels[pairs[agree, 0]] - reference.pixels[pairs[agree, 1]], axis=1)


def one_start(query: Features, reference: Features, known: np.ndarray, coarse: int, seed: int):
    """(seconds, result, whether it came coarse to fine) of one start with ``coarse``
    (0: all with all)."""
    began = time.perf_counter()
    found = pose_from_matches(query, reference, torch.from_numpy(known), 20, seed, coarse)
    seconds = time.perf_counter() - began
    fine = coarse > 0 and coarse_to_fine(query, reference, known, 20, seed, coarse) is not None
    return seconds, found, fine


def gap_rows(
    total: int, poses: dict, described: dict, gap: int, counts: list[int], every: int
) -> tuple[list[str], np.ndarray]:
    """The table rows of one gap (frames ``poses`` and ``described`` by index), and how
    far its agreeing features moved."""
    pairs = [(i, i + gap) for i in range(0, total - gap, every)]
    results: dict[int, list] = {count: [] for count in [0, *counts]}
    moved: list[np.ndarray] = []
    for earlier, later in pairs:
        known, truth = poses[earlier], poses[later]
        query, reference = described[later], described[earlier]
        for coarse, entries in results.items():
            seconds, found, fine = one_start(query, reference, known, coarse, later)
            error = None
            if found is not None:
                apart = pose_distance(torch.from_numpy(found.pose), torch.from_numpy(truth))
                error = (float(apart[0]) * 1e3, float(np.degrees(float(apart[1]))))
            entries.append((seconds, found, error, fine))
            if coarse == 0 and found is not None:
                relative = np.linalg.inv(known) @ found.pose
                moved.append(displacement_px(query, reference, relative))
    rows = [row(gap, coarse, entries) for coarse, entries in results.items()]
    return rows, np.concatenate(moved) if moved else np.zeros(0)


def row(gap: int, coarse: int, entries: list) -> str:
    """One table row: ``entries`` of (seconds, result, came coarse to fine, error)."""
    errors = np.array([e for _, _, e, _ in entries if e is not None]).reshape(-1, 2)
    inliers = [found.inliers for _, found, _, _ in entries if found is not None]
    fine = "-" if coarse == 0 else f"{np.mean([f for *_, f in entries]):.0%}"
    error = "-"
    if len(errors):
        error = (
            f"{np.median(errors[:, 0]):.1f} / {errors[:, 0].max():.1f} mm, "
            f"{np.median(errors[:, 1]):.2f} / {errors[:, 1].max():.2f} deg"
        )
    seconds = np.mean([s for s, *_ in entries])
    return (
        f"| {gap} | {coarse or 'all with all'} | {len(entries)} | {seconds * 1e3:.1f} ms "
        f"| {fine} | {len(errors)} | {np.median(inliers) if inliers else 0:.0f} | {error} |"
    )


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        config = load_config(args.config, [f"data.path={args.data}"])
        sequence = open_sequence(config.data)
    except (InputError, ConfigError) as error:
        print(f"coarse_start.py: {error}", file=sys.stderr)
        return 2
    torch.set_num_threads(args.threads)
    opencv().setNumThreads(args.threads)
    total = len(sequence)
    wanted = sorted(
        {i for gap in args.gaps for i in range(0, total - gap, args.every)}
        | {i + gap for gap in args.gaps for i in range(0, total - gap, args.every)}
    )
    orb = config.tracking.features
    poses, described = {}, {}
    for i in wanted:
        frame = sequence[i]
        if frame.pose_gt is None:
            print(f"coarse_start.py: {args.data}: frame {i} has no ground truth", file=sys.stderr)
            return 2
        poses[i] = frame.pose_gt
        described[i] = orb_features(frame.rgb, frame.depth, frame.intrinsics, orb)
    print(f"## coarse_start: {args.data} ({total} frames)")
    print("")
    print(f"{cpu_model()}, {args.threads} thread(s), ORB {orb.count} features")
    print("")
    print(
        "| gap | coarse | pairs | time per start | coarse to fine | starts | matches agreeing "
        "| error median / largest |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---|")
    moved = {}
    for gap in args.gaps:
        rows, moved[gap] = gap_rows(total, poses, described, gap, args.coarse, args.every)
        print("\n".join(rows))
    print("")
    print("| gap | features agreeing | moved median | 99th percentile | largest |")
    print("|---:|---:|---:|---:|---:|")
    for gap, shifts in moved.items():
        if len(shifts):
            print(
                f"| {gap} | {len(shifts)} | {np.median(shifts):.1f} px | "
                f"{np.percentile(shifts, 99):.1f} px | {shifts.max():.1f} px |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
