"""Where a run's frame-to-frame error sits: at its keyframes or between them.

Mapping refines keyframe poses; without ``mapping.carry_frames`` the frames between
keyframes keep their tracked poses, so every keyframe can become a step in the
trajectory. This splits a finished run's per-frame RPE (``eslam.evaluate.trajectory.
relative_pose_error``, delta 1) into the pairs with a keyframe in them and the others,
and its ATE (SE(3) alignment of the whole trajectory) into keyframes and other frames.
The keyframes are those of the run's checkpoint (map.pt).

    python benchmarks/keyframe_steps.py RUN_DIR [RUN_DIR ...]

Prints one markdown row per run (docs/results.md takes them by hand).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from eslam.errors import InputError
from eslam.evaluate.trajectory import (
    absolute_trajectory_error,
    pair_errors,
    relative_pose_error,
)
from eslam.io.checkpoint import load_checkpoint
from eslam.io.trajectory import read_run_trajectories


def rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else float("nan")


def split_errors(estimated: np.ndarray, truth: np.ndarray, keyframes: set[int]) -> dict:
    """RPE (mm, deg) of the pairs (i, i+1) with a keyframe in them and of the others;
    ATE (cm) of the keyframes and of the other frames, after one SE(3) alignment."""
    errors = pair_errors(estimated, truth)
    with_keyframe = np.array([i in keyframes or i + 1 in keyframes for i in errors.first])
    out = {}
    for name, chosen in (("keyframe", with_keyframe), ("other", ~with_keyframe)):
        if not chosen.any():
            out[f"rpe_{name}"] = (float("nan"), float("nan"), 0)
            continue
        out[f"rpe_{name}"] = (
            1000 * rms(errors.translation[chosen]),
            rms(errors.rotation[chosen]),
            int(chosen.sum()),
        )
    ate = absolute_trajectory_error(estimated, truth)
    is_keyframe = np.array([i in keyframes for i in range(len(estimated))])
    out["ate"] = 100 * ate.rmse
    out["ate_keyframes"] = 100 * rms(ate.errors[is_keyframe])
    out["ate_others"] = 100 * rms(ate.errors[~is_keyframe])
    out["rpe"] = relative_pose_error(estimated, truth)
    return out


def run_row(run: Path) -> str:
    """The markdown row of the run in ``run``."""
    _, estimated, truth = read_run_trajectories(run, "map.pt")
    state = load_checkpoint(run / "map.pt")
    keyframes = {int(i) for i in state["keyframes"]["frame_indices"]}
    e = split_errors(estimated, truth, keyframes)
    kf, other = e["rpe_keyframe"], e["rpe_other"]
    return (
        f"| {run.name} | {len(keyframes)} | {1000 * e['rpe'].translation_rmse:.2f} mm / "
        f"{e['rpe'].rotation_rmse:.3f} deg | {kf[0]:.2f} mm / {kf[1]:.3f} deg ({kf[2]}) | "
        f"{other[0]:.2f} mm / {other[1]:.3f} deg ({other[2]}) | {e['ate']:.3f} cm | "
        f"{e['ate_keyframes']:.3f} / {e['ate_others']:.3f} cm |"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="finished run folders")
    args = parser.parse_args(argv)
    print(
        "| run | keyframes | RPE | pairs with a keyframe | other pairs | ATE "
        "| ATE keyframes / others |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    try:
        for run in args.runs:
            print(run_row(run))
    except InputError as error:
        print(f"keyframe_steps.py: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
