"""How far the map moved each frame from its start of image features, and what that
did to the frame's step.

A frame started from features (``tracking.start: features``) records in timings.json
the matches that agreed on its start (``tracking_start_matches``), how far the tracker
moved the camera from it (``tracking_start_shift_m``) and whether the start overruled
the tracker (``tracking_overruled``: the frame kept the features' pose; docs/tracking.md
"When the features overrule the map"). Against the ground truth this prints, per run,
the frames the rule's thresholds pick (at least ``--matches`` matches, moved more than
``--shift``) and the error of the step into each (the RPE of the pair (i - 1, i), mm):
with the rule off these are the map's poses, with it on the features'; beside each,
the shift and the share of its points that fit the map.

    python benchmarks/start_shift.py RUN_DIR [RUN_DIR ...] [--matches 300] [--shift 0.05]

Prints one markdown row per run (docs/results.md takes them by hand).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.errors import InputError
from eslam.evaluate.trajectory import absolute_trajectory_error, pair_errors
from eslam.io.trajectory import read_run_trajectories


@dataclass(frozen=True)
class ShiftReport:
    """One run's frames by the rule's thresholds (module doc).

    Attributes:
        ate_cm: the run's ATE RMSE (SE(3) alignment).
        from_features: frames whose start came from features and whose tracker passed.
        shift_mm: the median, 99th percentile and largest shift of those frames, mm.
        picked: frames over both thresholds (index in the run).
        overruled: of ``picked``, those the start overruled.
        step_mm: the error of the step into each frame of ``picked``, mm.
        picked_shift_mm: how far the tracker moved each of them from its start, mm.
        picked_inliers: the share of each one's points that fit the map.
        other_step_mm: the median step error of the other frames from features, mm.
    """

    ate_cm: float
    from_features: int
    shift_mm: tuple[float, float, float]
    picked: list[int]
    overruled: list[int]
    step_mm: list[float]
    picked_shift_mm: list[float]
    picked_inliers: list[float]
    other_step_mm: float


def shift_report(
    estimated: np.ndarray, truth: np.ndarray, timings: dict, matches: int, shift: float
) -> ShiftReport:
    """The report of a run with poses ``estimated``, ground truth ``truth`` (both
    (N, 4, 4)) and per-frame lists ``timings`` (timings.json)."""
    n = len(estimated)
    column = {
        key: np.array([np.nan if v is None else v for v in timings[key][:n]], dtype=np.float64)
        for key in (
            "tracking_start_matches",
            "tracking_start_shift_m",
            "tracking_overruled",
            "tracking_inlier_fraction",
        )
    }
    agreed, moved = column["tracking_start_matches"], column["tracking_start_shift_m"]
    from_features = np.isfinite(moved)
    picked = from_features & (agreed >= matches) & (moved > shift)
    steps = np.full(n, np.nan)
    errors = pair_errors(estimated, truth)
    steps[errors.first + 1] = 1000 * errors.translation
    other = from_features & ~picked & np.isfinite(steps)
    chosen = np.flatnonzero(picked)
    return ShiftReport(
        ate_cm=100 * absolute_trajectory_error(estimated, truth).rmse,
        from_features=int(from_features.sum()),
        shift_mm=tuple(float(v) for v in 1000 * np.percentile(moved[from_features], [50, 99, 100])),
        picked=[int(i) for i in chosen],
        overruled=[int(i) for i in chosen if column["tracking_overruled"][i] == 1],
        step_mm=[float(steps[i]) for i in chosen],
        picked_shift_mm=[float(1000 * moved[i]) for i in chosen],
        picked_inliers=[float(column["tracking_inlier_fraction"][i]) for i in chosen],
        other_step_mm=float(np.nanmedian(steps[other])) if other.any() else float("nan"),
    )


def read_run(run: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """A finished run's poses, ground truth and timings.json."""
    _, estimated, truth = read_run_trajectories(run, "timings.json")
    timings = json.loads((run / "timings.json").read_text())
    if "tracking_start_shift_m" not in timings:
        raise InputError(
            run / "timings.json",
            "has no tracking_start_shift_m",
            "give a run that started its frames from features (tracking.start: features)",
        )
    return estimated, truth, timings


def run_row(run: Path, matches: int, shift: float) -> str:
    """The markdown row of the run in ``run``."""
    r = shift_report(*read_run(run), matches, shift)
    steps = ", ".join(
        f"{i}{'*' if i in r.overruled else ''}: {step:.0f} "
        f"({moved / 10:.1f} cm, {100 * share:.0f} %)"
        for i, step, moved, share in zip(
            r.picked, r.step_mm, r.picked_shift_mm, r.picked_inliers, strict=True
        )
    )
    return (
        f"| {run} | {r.ate_cm:.2f} cm | {r.from_features} | "
        f"{r.shift_mm[0]:.1f} / {r.shift_mm[1]:.1f} / {r.shift_mm[2]:.1f} mm | "
        f"{len(r.picked)} ({len(r.overruled)} overruled) | {steps or '-'} | "
        f"{r.other_step_mm:.1f} mm |"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="finished run folders")
    parser.add_argument("--matches", type=int, default=300, help="agreeing matches (300)")
    parser.add_argument("--shift", type=float, default=0.05, help="metres moved (0.05)")
    args = parser.parse_args(argv)
    print(
        "| run | ATE | frames from features | shift median / 99 % / largest "
        "| frames over both thresholds | their step error, mm (* overruled; the shift, inliers) "
        "| other frames' step error, median |"
    )
    print("|---|---:|---:|---:|---:|---|---:|")
    try:
        for run in args.runs:
            print(run_row(run, args.matches, args.shift))
    except InputError as error:
        print(f"start_shift.py: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
