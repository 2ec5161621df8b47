"""Which trajectory agrees better with the depth images: a run's estimate or the ground truth?

ATE measures an estimate against a reference and so counts the reference's own errors
as the estimate's. This reads a run's ``trajectory.txt`` and the sequence's ground
truth and scores both on the data itself (:mod:`eslam.evaluate.depth_consistency`):
for frame pairs (i, i + gap), the median |depth residual| of frame i's points moved
into frame i + gap by each trajectory, over the same pixels for both. Lower is more
consistent. It then lists the single-frame steps where the ground truth disagrees with
the depth most; the translation RPE of the steps by their place in the mapping cycle (a
mapped frame's pose is refined by mapping as well); and the ATE that a copy of the
ground truth with its worst step replaced by the estimate's scores against the ground
truth (what a trajectory perfect elsewhere but following the depth at that step
scores); and, per ``--segment`` frames, where the ATE builds up, how far each
trajectory moves there and how well each agrees with the depth there. No SLAM runs
here.

    python benchmarks/trajectory_consistency.py --config configs/sevenscenes/redkitchen.yaml \\
        --data ../shared/data/7scenes-redkitchen --run RUN_FOLDER
"""

from __future__ import annotations

import argparse
import datetime
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import DEFAULT_DOCS, command_line, publish

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.evaluate.depth_consistency import pair_consistency
from eslam.evaluate.trajectory import absolute_trajectory_error, relative_pose_error
from eslam.io.trajectory import read_trajectory


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", type=Path, required=True)
    parser.add_argument("--data", type=Path, required=True, help="the sequence folder")
    parser.add_argument("--run", type=Path, required=True, help="a run folder or trajectory")
    parser.add_argument("--gaps", type=int, nargs="+", default=[10, 60])
    parser.add_argument("--step", type=int, default=10, help="frames between pairs")
    parser.add_argument("--every", type=int, default=4, help="pixel subsampling")
    parser.add_argument("--inlier-cm", type=float, default=5.0)
    parser.add_argument("--worst", type=int, default=3, help="single steps listed")
    parser.add_argument("--segment", type=int, default=50, help="frames per segment row")
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("--note", default="")
    return parser.parse_args(argv)


def replaced_step(poses: np.ndarray, other: np.ndarray, index: int) -> np.ndarray:
    """``poses`` with the relative motion from ``index - 1`` to ``index`` taken from
    ``other`` and every later pose moved with it (the motions after are kept)."""
    moved = poses.copy()
    step = np.linalg.inv(other[index - 1]) @ other[index]
    correction = poses[index - 1] @ step @ np.linalg.inv(poses[index])
    moved[index:] = correction @ poses[index:]
    return moved


def net_motion(poses: np.ndarray, hop: int) -> float:
    """Sum of the camera's displacements |t(i + hop) - t(i)| over hops of ``hop`` frames
    (metres): how far it travels, with the per-frame jitter averaged out."""
    positions = poses[::hop, :3, 3]
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


def segment_rows(
    estimate: np.ndarray,
    ground_truth: np.ndarray,
    errors: np.ndarray,
    pair_medians: dict[int, np.ndarray],
    length: int,
    hop: int,
) -> list[str]:
    """One markdown row per ``length`` frames: the ATE errors' RMS there (cm, from the
    whole trajectory's alignment), how far each trajectory travels (:func:`net_motion`),
    and the median depth residual of the pairs starting there (``pair_medians``: start
    frame -> [ground truth, estimate] metres)."""
    rows = []
    for start in range(0, len(estimate) - 1, length):
        end = min(start + length, len(estimate) - 1)
        span = slice(start, end + 1)
        truth_motion = net_motion(ground_truth[span], hop)
        estimate_motion = net_motion(estimate[span], hop)
        inside = [m for i, m in pair_medians.items() if start <= i < end]
        residuals = np.median(np.stack(inside), axis=0) if inside else np.full(2, np.nan)
        # a hop longer than the segment measures no motion there: no ratio
        ratio = f"{estimate_motion / truth_motion:.3f}" if truth_motion > 0 else "-"
        rows.append(
            f"| {start}-{end} | {100 * np.sqrt(np.mean(errors[span] ** 2)):.2f} "
            f"| {100 * truth_motion:.1f} | {100 * estimate_motion:.1f} "
            f"| {ratio} "
            f"| {1000 * residuals[0]:.2f} | {1000 * residuals[1]:.2f} |"
        )
    return rows


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    config = load_config(args.config, [f"data.path={args.data}", "data.register_colour=false"])
    sequence = open_sequence(config.data)
    times, estimate = read_trajectory(args.run)
    ground_truth = sequence.gt_poses()
    count = len(estimate)
    if ground_truth is None or count > len(sequence):
        raise SystemExit(f"{args.run}: needs a sequence with ground truth and >= {count} frames")
    if not np.allclose(times, sequence.timestamps()[:count]):
        raise SystemExit(f"{args.run}: its timestamps are not the sequence's first {count}")
    ground_truth = ground_truth[:count]
    depths = [sequence[i].depth for i in range(count)]
    intrinsics = sequence.intrinsics
    inlier = args.inlier_cm / 100

    def medians(i: int, j: int) -> np.ndarray:
        poses = [(ground_truth[i], ground_truth[j]), (estimate[i], estimate[j])]
        return pair_consistency(depths[i], depths[j], intrinsics, poses, inlier, args.every).medians

    rows = []
    first_gap_pairs: dict[int, np.ndarray] = {}
    for gap in args.gaps:
        by_start = {i: medians(i, i + gap) for i in range(0, count - gap, args.step)}
        by_start = {i: m for i, m in by_start.items() if np.isfinite(m).all()}
        if gap == args.gaps[0]:
            first_gap_pairs = by_start
        if not by_start:  # no pair this far apart sees the same surface (e.g. half a lap)
            rows.append(f"| {gap} | 0 | - | - | - |")
            continue
        pairs = np.array(list(by_start.values()))
        better = int((pairs[:, 1] < pairs[:, 0]).sum())
        rows.append(
            f"| {gap} | {len(pairs)} | {1000 * np.median(pairs[:, 0]):.2f} "
            f"| {1000 * np.median(pairs[:, 1]):.2f} | {better} of {len(pairs)} |"
        )
    steps = np.array([medians(i - 1, i) for i in range(1, count)])
    worst = np.argsort(-(steps[:, 0] - steps[:, 1]))[: args.worst] + 1
    step_rows = []
    for index in worst:
        gt_step = np.linalg.inv(ground_truth[index - 1]) @ ground_truth[index]
        est_step = np.linalg.inv(estimate[index - 1]) @ estimate[index]
        step_rows.append(
            f"| {index - 1} -> {index} | {1000 * np.linalg.norm(gt_step[:3, 3]):.1f} "
            f"| {1000 * np.linalg.norm(est_step[:3, 3]):.1f} "
            f"| {1000 * steps[index - 1, 0]:.2f} | {1000 * steps[index - 1, 1]:.2f} |"
        )
    every = config.mapping.every
    step_errors = np.array(
        [
            relative_pose_error(
                estimate[i - 1 : i + 1], ground_truth[i - 1 : i + 1]
            ).translation_rmse
            for i in range(1, count)
        ]
    )
    position = np.arange(1, count) % every
    estimate_ate = absolute_trajectory_error(estimate[:, :3, 3], ground_truth[:, :3, 3])
    frame_position = np.arange(count) % every
    cycle_rows = [
        f"| {k}{' (mapped frame)' if k == 0 else ''} | {int((position == k).sum())} "
        f"| {1000 * np.median(step_errors[position == k]):.2f} "
        f"| {1000 * np.sqrt(np.mean(step_errors[position == k] ** 2)):.2f} "
        f"| {100 * np.sqrt(np.mean(estimate_ate.errors[frame_position == k] ** 2)):.2f} |"
        for k in range(every)
    ]
    spliced = replaced_step(ground_truth, estimate, int(worst[0]))
    floor = absolute_trajectory_error(spliced[:, :3, 3], ground_truth[:, :3, 3])
    floor_scale = absolute_trajectory_error(
        spliced[:, :3, 3], ground_truth[:, :3, 3], with_scale=True
    ).alignment.scale
    hop = args.gaps[0]
    segments = segment_rows(
        estimate, ground_truth, estimate_ate.errors, first_gap_pairs, args.segment, hop
    )
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## trajectory_consistency, {now}",
        "",
        f"- command: `{command_line('benchmarks/trajectory_consistency.py', argv)}`",
        f"- {count} frames; pairs every {args.step} frames; every {args.every}th pixel; "
        f"pixels within {args.inlier_cm:g} cm under both trajectories; figures: median "
        "over pairs of each pair's median |depth residual| (lower = more consistent)",
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    lines += [
        "",
        "| gap (frames) | pairs | ground truth (mm) | estimate (mm) "
        "| pairs where the estimate agrees better |",
        "|---:|---:|---:|---:|---:|",
        *rows,
        "",
        "Single steps where the ground truth disagrees with the depth most (against the estimate):",
        "",
        "| step | ground-truth motion (mm) | estimated motion (mm) | ground truth (mm) "
        "| estimate (mm) |",
        "|---|---:|---:|---:|---:|",
        *step_rows,
        "",
        f"Translation RPE of the steps into frame i by i mod mapping.every ({every}): the "
        "mapped frames' poses are also refined by mapping (`mapping.optimise_poses`); "
        "last column: the RMS of the ATE errors of those frames i:",
        "",
        "| i mod every | steps | median (mm) | RMSE (mm) | ATE errors RMS (cm) |",
        "|---|---:|---:|---:|---:|",
        *cycle_rows,
        "",
        f"- ATE RMSE of the estimate: {100 * estimate_ate.rmse:.2f} cm. The ground truth with "
        f"its step {worst[0] - 1} -> {worst[0]} replaced by the estimate's scores "
        f"{100 * floor.rmse:.2f} cm against the ground truth (Sim(3) scale "
        f"{floor_scale:.4f}): what a trajectory equal to the ground truth everywhere else "
        "but moving as the estimate does at that step scores.",
        "",
        f"Where the ATE builds up, by {args.segment} frames: RMS of the ATE errors there (the "
        f"whole run's alignment), how far each trajectory moves (sum of {hop}-frame "
        f"displacements), and the median depth residual of the {hop}-frame pairs starting "
        "there:",
        "",
        "| frames | ATE errors RMS (cm) | ground-truth motion (cm) | estimated motion (cm) "
        "| estimate / ground truth | ground truth (mm) | estimate (mm) |",
        "|---|---:|---:|---:|---:|---:|---:|",
        *segments,
        "",
    ]
    publish("\n".join(lines), args.docs, args.no_append)


if __name__ == "__main__":
    main()
