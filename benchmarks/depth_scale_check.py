"""Does a sequence's depth agree in scale with its ground-truth poses?

For frame pairs (i, i + gap), the valid depth of frame i, multiplied by a candidate
scale s, is moved by the ground-truth relative pose and projected into frame j, where it
is compared with frame j's depth times the same s. If the depth were s* times too small
relative to the poses' translations, the residual would be smallest at s = s*. The
source pixels are fixed at s = 1 (residual under ``--inlier-cm``, which drops
occlusions and invalid depth), so every scale is scored on the same points.

Used to tell the two causes of the scale component of the 7-Scenes redkitchen trajectory
apart (docs/results.md, "Data checks (no SLAM)"): a depth/pose scale mismatch in the
data, or tracking that lags the true motion. No SLAM runs here; it reads the sequence
only.

    python benchmarks/depth_scale_check.py --config configs/sevenscenes/redkitchen.yaml \\
        --data ../shared/data/7scenes-redkitchen
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
from eslam.evaluate.depth_consistency import depth_residuals
from eslam.types import Frame


def pair_residuals(
    source: Frame, target: Frame, scales: np.ndarray, inlier_m: float, every: int
) -> tuple[np.ndarray, float]:
    """Median |depth residual| (m) of ``source`` seen from ``target``, per scale
    (:func:`eslam.evaluate.depth_consistency.depth_residuals` with the ground truth).

    Returns:
        (S,) medians over the source pixels that are inliers at s = 1, and the
        baseline (m) between the two ground-truth camera centres.
    """

    def residual(scale: float) -> np.ndarray:
        return depth_residuals(
            source.depth, target.depth, source.intrinsics,
            source.pose_gt, target.pose_gt, every, scale,
        )  # fmt: skip

    inliers = np.abs(np.nan_to_num(residual(1.0), nan=np.inf)) < inlier_m
    medians = []
    for scale in scales:
        values = residual(float(scale))[inliers]
        values = values[np.isfinite(values)]
        medians.append(float(np.median(np.abs(values))) if values.size else float("nan"))
    relative = np.linalg.inv(target.pose_gt) @ source.pose_gt
    return np.array(medians), float(np.linalg.norm(relative[:3, 3]))


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", type=Path, required=True)
    parser.add_argument("--data", type=Path, required=True, help="the sequence folder")
    parser.add_argument("--gap", type=int, default=40, help="frames between the two views")
    parser.add_argument("--step", type=int, default=20, help="frames between pairs")
    parser.add_argument("--min-baseline-cm", type=float, default=15.0)
    parser.add_argument("--inlier-cm", type=float, default=5.0)
    parser.add_argument("--every", type=int, default=4, help="pixel subsampling")
    parser.add_argument("--scale-range", type=float, default=0.06, help="s in 1 +- this")
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    config = load_config(args.config, [f"data.path={args.data}"])
    sequence = open_sequence(config.data)
    scales = np.round(np.arange(1 - args.scale_range, 1 + args.scale_range + 1e-9, 0.005), 4)
    rows, best = [], []
    for i in range(0, len(sequence) - args.gap, args.step):
        source, target = sequence[i], sequence[i + args.gap]
        if source.pose_gt is None or target.pose_gt is None:
            continue
        medians, baseline = pair_residuals(source, target, scales, args.inlier_cm / 100, args.every)
        if baseline * 100 < args.min_baseline_cm or not np.isfinite(medians).any():
            continue
        one = int(np.argmin(np.abs(scales - 1.0)))
        k = int(np.nanargmin(medians))
        best.append(scales[k])
        rows.append(
            f"| {i} -> {i + args.gap} | {baseline * 100:.1f} | {medians[one] * 1000:.1f} "
            f"| {scales[k]:.3f} | {medians[k] * 1000:.1f} |"
        )
    if not rows:
        raise SystemExit("no frame pair with ground truth and enough baseline")
    best = np.array(best)
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    section = "\n".join(
        [
            f"## depth_scale_check, {now}",
            "",
            f"- command: `{command_line('benchmarks/depth_scale_check.py', argv)}`",
            f"- {len(rows)} pairs {args.gap} frames apart with >= {args.min_baseline_cm:g} cm "
            f"baseline; scales {scales[0]:.3f}-{scales[-1]:.3f} in steps of 0.005; "
            f"median |residual| over the pixels within {args.inlier_cm:g} cm at s = 1",
            f"- best scale per pair: median {np.median(best):.3f}, range "
            f"{best.min():.3f}-{best.max():.3f}; {int((best > 1).sum())} pairs above 1, "
            f"{int((best < 1).sum())} below, {int((best == 1).sum())} at 1",
            "",
            "| pair | baseline (cm) | median residual at s = 1 (mm) | best s "
            "| median residual at best s (mm) |",
            "|---|---:|---:|---:|---:|",
            *rows,
            "",
        ]
    )
    publish(section, args.docs, args.no_append)


if __name__ == "__main__":
    main()
