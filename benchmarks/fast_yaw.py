"""Fast yaw on the synthetic room: failed frames, the longest loss and the ATE per rate.

For each ``--steps`` value (degrees of yaw per frame, +-30 % slowly varying; pitch and
roll swing too, bounded: :mod:`eslam.synthetic.trajectory`) the synthetic room is
written with exact ground truth and run with ``--config`` (default the demo's CPU
preset) inside the scene's own bound. One markdown row per rate: degrees per second at
``--fps``, failed frames, the longest run of them, whether the run ended tracked, ATE
and rotation RPE (each run's metrics.json; docs/evaluation.md).

    python benchmarks/fast_yaw.py --steps 3 6 --frames 40 --out /tmp/fast_yaw

Prints the table only (docs/results.md takes its rows by hand).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import torch

from eslam.cli.args import image_size
from eslam.config import load_config
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
from eslam.workflows.demo import DEMO_CONFIG


@dataclass(frozen=True)
class YawRun:
    """One rate's run: its yaw step (degrees per frame) and its metrics.json."""

    step_deg: float
    metrics: dict


def run_rate(
    step_deg: float,
    out: Path,
    config: Path,
    frames: int,
    size: tuple[int, int],
    seed: int,
    overrides: tuple[str, ...] = (),
) -> YawRun:
    """Write the room at ``step_deg`` of yaw per frame under ``out`` and run it."""
    data = out / f"data-{step_deg:g}"
    synth = SynthConfig(
        frames=frames, width=size[0], height=size[1], seed=seed, step_rotation_deg=step_deg
    )
    write_synthetic_sequence(data, synth, overwrite=True)
    settings = [
        f"data.path={data}",
        f"scene.bound={read_synthetic_bound(data)}",
        "output.mesh=false",
        "output.progress=false",
        *overrides,
    ]
    result = run_slam(load_config(config, settings), out / f"run-{step_deg:g}", overwrite=True)
    return YawRun(step_deg, result.metrics)


def table(runs: list[YawRun], fps: float) -> str:
    """The markdown table of ``runs`` (module doc)."""
    lines = [
        f"| yaw (deg/frame) | deg/s at {fps:g} fps | failed frames | longest run "
        "| ended tracked | ATE RMSE (cm) | rotation RPE (deg) |",
        "|---:|---:|---:|---:|---|---:|---:|",
    ]
    for run in runs:
        m = run.metrics
        lines.append(
            f"| {run.step_deg:g} | {run.step_deg * fps:g} | {m.get('tracking_failures', '-')} "
            f"| {m.get('tracking_failed_longest_run', '-')} "
            f"| {m.get('tracking_ended_tracked', '-')} | {m['ate_rmse_cm']:.3f} "
            f"| {m['rpe_rotation_rmse_deg']:.3f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--steps", type=float, nargs="+", required=True, help="deg/frame")
    parser.add_argument("--out", type=Path, required=True, help="folder for data and runs")
    parser.add_argument("--config", type=Path, default=DEMO_CONFIG, help="(configs/demo.yaml)")
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--size", type=image_size, default=(160, 120), help="WxH (160x120)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--fps", type=float, default=30.0, help="for the deg/s column (30)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    args = parser.parse_intermixed_args(argv)
    if any(step <= 0 for step in args.steps) or args.frames < 3:
        parser.error("--steps must be positive and --frames at least 3")
    torch.set_num_threads(args.threads)
    runs = [
        run_rate(
            step, args.out, args.config, args.frames, args.size, args.seed, tuple(args.overrides)
        )
        for step in args.steps
    ]
    print(table(runs, args.fps))


if __name__ == "__main__":
    main()
