"""The time offset between a run's camera and its motion-capture ground truth.

TUM's tools (and eslam's reader, as the ESLAM release does) pair each frame with the
nearest ground-truth pose in time, with no offset. If the camera's clock runs behind or
ahead of the motion capture, every fast motion adds an error that is the ground truth's
and not the tracker's. This scores a finished run's trajectory.txt against
groundtruth.txt interpolated at each frame's time plus an offset (positions linearly,
rotations by slerp), for a range of offsets, and prints the ATE RMSE (SE(3) alignment)
per offset and the best one.

    python benchmarks/time_offset.py RUN_DIR .../rgbd_dataset_freiburg1_xyz/groundtruth.txt \\
        [--windows 50]

RUN_DIR may also be a trajectory file in TUM's format (a published estimate). An
offset that lowers the ATE much below the zero row says the pairing, not the tracker,
holds part of the error. The published figures use no offset; so do docs/results.md's
rows.

``--windows N`` also asks whether the offset is the same all along: per N frames, the
lag that best explains the estimate's error (SE(3)-aligned over the whole trajectory at
no offset) as the ground truth's velocity times a delay (:func:`window_lags`). A
tracker that falls behind fast motion lags wherever the camera moves fast; a clock
that slips lags on one stretch and not the next, in every estimator alike.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from eslam.data.tum import read_groundtruth
from eslam.errors import InputError
from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.io.trajectory import read_tum_trajectory


def interpolated(times: np.ndarray, poses: np.ndarray, at: np.ndarray) -> np.ndarray:
    """(len(at), 4, 4) poses at times ``at`` (within ``times``): positions linearly,
    rotations by spherical linear interpolation between the neighbouring samples."""
    rotations = Slerp(times, Rotation.from_matrix(poses[:, :3, :3]))(at)
    out = np.tile(np.eye(4), (len(at), 1, 1))
    out[:, :3, :3] = rotations.as_matrix()
    for k in range(3):
        out[:, k, 3] = np.interp(at, times, poses[:, k, 3])
    return out


def offset_errors(
    times: np.ndarray,
    estimate: np.ndarray,
    truth_times: np.ndarray,
    truth: np.ndarray,
    offsets: np.ndarray,
) -> list[tuple[float, float, int]]:
    """(offset s, ATE RMSE cm, frames scored) per offset: the estimate at each time t
    against the ground truth at t + offset (frames whose t + offset lies outside the
    ground truth are left out)."""
    rows = []
    for offset in offsets:
        at = times + offset
        inside = (at >= truth_times[0]) & (at <= truth_times[-1])
        if inside.sum() < 3:
            rows.append((float(offset), float("nan"), int(inside.sum())))
            continue
        gt = interpolated(truth_times, truth, at[inside])
        error = absolute_trajectory_error(estimate[inside], gt).as_cm()["ate_rmse_cm"]
        rows.append((float(offset), float(error), int(inside.sum())))
    return rows


def window_lags(
    times: np.ndarray,
    estimate: np.ndarray,
    truth_times: np.ndarray,
    truth: np.ndarray,
    window: int,
) -> list[tuple[int, int, float, float]]:
    """(first frame, frames, lag s, ATE RMSE cm) per ``window`` frames of the estimate.

    The estimate is SE(3)-aligned onto the ground truth at each frame's time (no
    offset), as the ATE is; on each window the error's variation e_i - mean(e) is fitted
    by least squares as -lag * (v_i - mean(v)), v the ground truth's velocity at t_i
    (central difference over 10 ms): a positive lag is an estimate that trails the
    ground truth by that much time (it is where the truth was ``lag`` seconds earlier).
    Frames whose time lies outside the ground truth are left out.
    """
    inside = (times - 0.005 >= truth_times[0]) & (times + 0.005 <= truth_times[-1])
    times, estimate = times[inside], estimate[inside]
    gt = interpolated(truth_times, truth, times)[:, :3, 3]
    ahead = interpolated(truth_times, truth, times + 0.005)[:, :3, 3]
    behind = interpolated(truth_times, truth, times - 0.005)[:, :3, 3]
    velocity = (ahead - behind) / 0.01
    result = absolute_trajectory_error(estimate, interpolated(truth_times, truth, times))
    error = result.alignment.apply(estimate[:, :3, 3]) - gt
    rows = []
    for first in range(0, len(times), window):
        part = slice(first, first + window)
        e = error[part] - error[part].mean(axis=0)
        v = velocity[part] - velocity[part].mean(axis=0)
        energy = float((v * v).sum())
        lag = float(-(e * v).sum() / energy) if energy > 0 else float("nan")
        rmse = float(np.sqrt((result.errors[part] ** 2).mean()) * 100.0)
        rows.append((first, len(e), lag, rmse))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("run", type=Path, help="a run folder (its trajectory.txt)")
    parser.add_argument("groundtruth", type=Path, help="the sequence's groundtruth.txt")
    parser.add_argument(
        "--offsets",
        type=float,
        nargs=3,
        default=(-0.05, 0.05, 0.005),
        metavar=("FIRST", "LAST", "STEP"),
        help="seconds (default -0.05 0.05 0.005)",
    )
    parser.add_argument(
        "--windows", type=int, default=0, metavar="N", help="also the lag per N frames"
    )
    args = parser.parse_args(argv)
    try:
        path = args.run / "trajectory.txt" if args.run.is_dir() else args.run
        times, estimate = read_tum_trajectory(path)
        truth = read_groundtruth(args.groundtruth)
    except InputError as error:
        print(f"time_offset.py: {error}", file=sys.stderr)
        return 2
    first, last, step = args.offsets
    offsets = np.round(np.arange(first, last + step / 2, step), 6) + 0.0  # no -0.000
    rows = offset_errors(times, estimate, truth.timestamps, truth.poses, offsets)
    print("| ground truth at t + offset (s) | ATE RMSE (cm) | frames |")
    print("|---:|---:|---:|")
    for offset, error, frames in rows:
        print(f"| {offset:+.3f} | {error:.3f} | {frames} |")
    best = min(rows, key=lambda r: (np.nan_to_num(r[1], nan=np.inf), abs(r[0])))
    print(f"\nbest offset {best[0]:+.3f} s: ATE {best[1]:.3f} cm")
    if args.windows > 0:
        print("\n| frames | lag (ms; + = the estimate trails) | ATE RMSE there (cm) |")
        print("|---|---:|---:|")
        for first, count, lag, rmse in window_lags(
            times, estimate, truth.timestamps, truth.poses, args.windows
        ):
            print(f"| {first}-{first + count - 1} | {1000 * lag:+.1f} | {rmse:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
