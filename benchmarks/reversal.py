"""A camera that reverses on the synthetic room: the motion model's guess runs on the
wrong way. Failed frames, the ATE and the largest error after the reversal, per
starting-pose setting (docs/tracking.md, "Starting pose").

The room (``--size``, seed 0, ``--step`` cm and ``--yaw`` degrees per frame) is
rendered with exact ground truth; the camera goes forward ``--forward`` frames, then
back two frames at a time to frame 1 (:mod:`eslam.synthetic.edits`), so at the first
frame back the truth is two steps behind where the motion model expects one ahead.
Each ``--settings`` entry (``motion`` = ``tracking.start=motion``, ``features`` =
``tracking.start=features``, or any ``key=value,key=value``) is one run and one
markdown row: failed frames, the ATE, the largest position error from the reversal on
(no alignment: frame 0 starts at its ground truth), tracking seconds per frame.

    python benchmarks/reversal.py --out /tmp/reversal

Trailing KEY=VALUE arguments are config overrides for every run. Prints the table only
(docs/results.md takes its rows by hand).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from eslam.cli.args import image_size
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig
from eslam.synthetic.edits import SequenceEdit, reversal, write_edited_sequence
from eslam.synthetic.runs import synthetic_run_config
from eslam.workflows.demo import DEMO_CONFIG

PRESETS = {"motion": ("tracking.start=motion",), "features": ("tracking.start=features",)}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for data and runs")
    parser.add_argument("--config", type=Path, default=DEMO_CONFIG, help="(configs/demo.yaml)")
    parser.add_argument("--size", type=image_size, default=(160, 120), help="WxH (160x120)")
    parser.add_argument("--step", type=float, default=2.0, help="cm per frame (2)")
    parser.add_argument("--yaw", type=float, default=2.0, help="degrees per frame (2)")
    parser.add_argument("--forward", type=int, default=10, help="frames before the reversal")
    parser.add_argument("--settings", nargs="+", default=["motion", "features"])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("overrides", nargs="*", help="KEY=VALUE config overrides")
    args = parser.parse_args(argv)
    if args.forward < 4 or args.step <= 0 or args.yaw < 0:
        parser.error("--forward must be >= 4, --step positive, --yaw >= 0")
    torch.set_num_threads(args.threads)
    room = SynthConfig(
        frames=args.forward,
        width=args.size[0],
        height=args.size[1],
        seed=0,
        step_translation=args.step / 100.0,
        step_rotation_deg=args.yaw,
    )
    edit = SequenceEdit(reversal(args.forward))
    data = write_edited_sequence(args.out / "data", room, edit)
    lines = [
        "| start | failed frames | ATE RMSE | largest error from the reversal | tracking s/frame |",
        "|---|---:|---:|---:|---:|",
    ]
    for name in args.settings:
        settings = PRESETS.get(name, tuple(name.split(",")))
        config = synthetic_run_config(args.config, data, *args.overrides, *settings)
        run_dir = args.out / f"run-{len(lines) - 2}"
        result = run_slam(config, run_dir, overwrite=True)
        estimate = np.loadtxt(run_dir / "trajectory.txt")[:, 1:4]
        truth = np.loadtxt(run_dir / "trajectory_gt.txt")[:, 1:4]
        after = 100.0 * np.linalg.norm(estimate - truth, axis=1)[args.forward :].max()
        metrics = result.metrics
        timings = json.loads((run_dir / "timings.json").read_text(encoding="utf-8"))
        tracking_s = float(np.mean(timings["tracking_s"][1:]))
        lines.append(
            f"| {name} | {metrics['tracking_failures']} | {metrics['ate_rmse_cm']:.2f} cm "
            f"| {after:.2f} cm | {tracking_s:.3f} |"
        )
    print("\n".join(lines))


if __name__ == "__main__":
    main()
