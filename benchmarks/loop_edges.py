"""Were a run's loop edges closer to the ground truth than the estimate they corrected?

A loop edge (docs/loops.md) is the relative pose that registration measured between a
new keyframe i and an earlier one j. A pose graph can pull the trajectory toward the
truth only where such edges are closer to the truth than the trajectory's own relative
pose T_j^-1 T_i. For every loop the run in RUN accepted (its ``loops.json``) this
compares both with the ground truth's (RUN's ``trajectory_gt.txt``): the edge, and the
estimate of ``--estimate`` (a finished run of the same frames, typically the same
config with loop closure off; by default RUN itself, whose trajectory the loops have
already corrected). Rows: every accepted loop, then by how many frames apart the two
keyframes are; ``--min-inliers F`` keeps only the loops with at least that share of
inliers (would a stricter gate keep better edges?). ``--odometry`` judges the edges
between consecutive keyframes that a run with ``mapping.loops.odometry: icp`` measured
(kept in its ``map.pt``) instead of its loops.

    python benchmarks/loop_edges.py RUN_WITH_LOOPS --estimate RUN_WITHOUT [--odometry]

Frame indices in ``loops.json`` are rows of the trajectories: runs of recorded frames
(a real-time run that dropped frames is refused). Prints the table only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from eslam.errors import InputError
from eslam.io.checkpoint import load_checkpoint
from eslam.io.trajectory import read_run_trajectories
from eslam.slam.loops.closer import COMPONENT, pose_difference
from eslam.slam.loops.pose_graph import relative_pose

TIE_CM = 1e-6
"""An edge counts as closer only by more than this (cm): a tie is not a gain."""

GAPS = ((0, 100), (100, 300), (300, None))
"""Frame gaps the table groups loops by: [low, high) frames apart, None = no limit."""


def accepted_loops(run: Path, min_inliers: float = 0.0) -> list[tuple[int, int, np.ndarray]]:
    """(frame, candidate frame, 4x4 relative pose) of each loop ``run`` accepted with at
    least ``min_inliers`` of its points on the candidate's surface (a stricter gate than
    the run's ``min_inlier_fraction``, to see whether it would keep better edges)."""
    path = run / "loops.json"
    if not path.is_file():
        raise InputError(path, "missing", "give a run made with mapping.loops.enabled=true")
    try:
        entries = json.loads(path.read_text())
        return [
            (int(e["frame"]), int(e["candidate_frame"]), np.array(e["relative_pose"], float))
            for e in entries
            if e["accepted"] and e["inlier_fraction"] >= min_inliers
        ]
    except (ValueError, KeyError, TypeError) as error:
        raise InputError(path, f"unreadable ({error})", "give a run's own loops.json") from error


def measured_odometry(run: Path) -> list[tuple[int, int, np.ndarray]]:
    """(later frame, earlier frame, 4x4 relative pose) of each odometry edge ``run``
    measured by ICP and kept (``mapping.loops.odometry: icp``; its map.pt)."""
    path = run / "map.pt"
    record = load_checkpoint(path).get("components", {}).get(COMPONENT, {}).get("odometry")
    if not record:
        raise InputError(
            path,
            "holds no measured odometry edges",
            "give a run made with mapping.loops.odometry=icp that closed a loop",
        )
    edges = []
    for key, pose in record.items():
        if pose is not None:  # refused: the run used the estimate's edge there
            earlier, later = (int(frame) for frame in key.split("-"))
            edges.append((later, earlier, np.reshape(np.asarray(pose, float), (4, 4))))
    return edges


def edge_errors(
    loops: list[tuple[int, int, np.ndarray]], estimate: np.ndarray, truth: np.ndarray
) -> np.ndarray:
    """(L, 5): frames apart, the edge's and the estimate's distance from the truth.

    Columns: i - j, edge cm, edge degrees, estimate cm, estimate degrees, where the
    truth is T*_j^-1 T*_i, the estimate T_j^-1 T_i and the edge is compared as measured
    (``pose_difference``: |t| and the angle of a^-1 b).
    """
    rows = []
    for i, j, edge in loops:
        real = relative_pose(truth[j], truth[i])
        edge_m, edge_deg = pose_difference(real, edge)
        est_m, est_deg = pose_difference(real, relative_pose(estimate[j], estimate[i]))
        rows.append((i - j, 100 * edge_m, edge_deg, 100 * est_m, est_deg))
    return np.array(rows, dtype=float).reshape(-1, 5)


def table(errors: np.ndarray) -> list[str]:
    """The markdown table of ``edge_errors`` rows: all loops, then by gap."""
    lines = [
        "| edges | frames apart | edge from the truth (cm / deg) "
        "| estimate from the truth (cm / deg) | edge closer (cm) |",
        "|---|---|---:|---:|---:|",
    ]
    groups = [("all", np.ones(len(errors), bool))]
    for low, high in GAPS:
        upper = np.inf if high is None else high
        name = f"{low}-{high}" if high is not None else f">= {low}"
        groups.append((name, (errors[:, 0] >= low) & (errors[:, 0] < upper)))
    for name, mask in groups:
        if not mask.any():
            continue
        part = errors[mask]
        edge, est = part[:, 1:3].mean(axis=0), part[:, 3:5].mean(axis=0)
        closer = int((part[:, 1] < part[:, 3] - TIE_CM).sum())
        lines.append(
            f"| {len(part)} | {name} | {edge[0]:.2f} / {edge[1]:.2f} "
            f"| {est[0]:.2f} / {est[1]:.2f} | {closer} of {len(part)} |"
        )
    return lines


def dropped_frames(run: Path) -> int:
    """Frames a real-time run dropped (metrics.json's ``frames_dropped``; 0 if absent)."""
    path = run / "metrics.json"
    return int(json.loads(path.read_text()).get("frames_dropped", 0)) if path.is_file() else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("run", type=Path, help="a finished run with loop closure on")
    parser.add_argument("--estimate", type=Path, help="the run whose relative poses to judge")
    parser.add_argument(
        "--min-inliers", type=float, default=0.0, help="only loops with this inlier share"
    )
    parser.add_argument(
        "--odometry", action="store_true", help="judge the measured odometry edges instead"
    )
    args = parser.parse_args(argv)
    if args.odometry and args.min_inliers:
        parser.error("--min-inliers gates loops: it does not apply with --odometry")
    try:
        if args.odometry:
            loops = measured_odometry(args.run)
        else:
            loops = accepted_loops(args.run, args.min_inliers)
        for run in {args.run, args.estimate or args.run}:
            if dropped_frames(run):
                raise InputError(run, "dropped frames", "give a run of recorded frames")
        times, estimate, truth = read_run_trajectories(args.run)
        if args.estimate is not None:
            times, estimate, _ = read_run_trajectories(args.estimate)
        if len(times) != len(truth):
            raise InputError(
                args.estimate, f"{len(times)} poses, not {len(truth)}", "run the same frames"
            )
        if not loops:
            raise InputError(args.run / "loops.json", "no accepted loop", "nothing to judge")
        if max(i for i, _, _ in loops) >= len(truth):
            raise InputError(args.run, "loops beyond its trajectory", "give its own folder")
        errors = edge_errors(loops, estimate, truth)
        if not np.isfinite(errors).all():
            raise InputError(args.run, "loops without ground truth", "give a run with it")
    except InputError as error:
        print(f"loop_edges.py: {error}", file=sys.stderr)
        return 2
    print("\n".join(table(errors)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
