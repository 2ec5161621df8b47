"""A forced loss on the synthetic room: frames without depth while the camera moves on,
then a return to places it mapped. Failed frames, recoveries and the error after the
return, with recovery on and off (docs/tracking.md, "Recovery").

The room (``--size``, seed 0, ``--yaw`` degrees per frame) is rendered with exact ground
truth; frames 0 to ``--mapped`` - 1 are tracked and mapped, the next ``--blind`` have no
depth, then the source frames ``--back`` come again (:mod:`eslam.synthetic.edits`). Each
``--settings`` entry (``on`` = the config as it is, ``off`` =
``tracking.recovery.enabled=false``, or any ``key=value,key=value``) is one run and one
markdown row: failed frames, the longest run of them, frames recovered (from another
start / relocalised), the first frame tracked back, the largest position error from
there to the end (no alignment: frame 0 starts at its ground truth), and the ATE.

    python benchmarks/forced_loss.py --out /tmp/forced_loss

Prints the table only (docs/results.md takes its rows by hand).
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
from eslam.synthetic.edits import SequenceEdit, return_after_blind, write_edited_sequence
from eslam.synthetic.runs import synthetic_run_config
from eslam.workflows.demo import DEMO_CONFIG

PRESETS = {"on": (), "off": ("tracking.recovery.enabled=false",)}


def row(name: str, run_dir: Path, back: int, metrics: dict) -> str:
    """One markdown row for the run in ``run_dir`` (module doc)."""
    estimate = np.loadtxt(run_dir / "trajectory.txt")
    truth = np.loadtxt(run_dir / "trajectory_gt.txt")
    errors = 100.0 * np.linalg.norm(estimate[:, 1:4] - truth[:, 1:4], axis=1)
    failed = json.loads((run_dir / "timings.json").read_text())["tracking_failed"]
    tracked = [i for i in range(back, len(failed)) if failed[i] == 0]
    first = tracked[0] if tracked else None
    after = f"{errors[first:].max():.2f} cm" if first is not None else "-"
    recovered = metrics["tracking_recovered_frames"]
    return (
        f"| {name} | {metrics['tracking_failures']} | {metrics['tracking_failed_longest_run']} "
        f"| {recovered['start']} / {recovered['relocalised']} "
        f"| {first if first is not None else 'never'} | {after} | {metrics['ate_rmse_cm']:.2f} cm |"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for data and runs")
    parser.add_argument("--config", type=Path, default=DEMO_CONFIG, help="(configs/demo.yaml)")
    parser.add_argument("--size", type=image_size, default=(120, 90), help="WxH (120x90)")
    parser.add_argument("--yaw", type=float, default=2.0, help="degrees per frame (2)")
    parser.add_argument("--mapped", type=int, default=10)
    parser.add_argument("--blind", type=int, default=5)
    parser.add_argument("--back", type=int, nargs="+", default=[3, 4, 5, 6])
    parser.add_argument("--settings", nargs="+", default=["on", "off"])
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    if args.mapped < 2 or args.blind < 0 or any(not 0 <= b < args.mapped for b in args.back):
        parser.error("--mapped must be >= 2, --blind >= 0, --back frames among the mapped")
    torch.set_num_threads(args.threads)
    room = SynthConfig(
        frames=args.mapped + args.blind,
        width=args.size[0],
        height=args.size[1],
        seed=0,
        step_rotation_deg=args.yaw,
    )
    order, blind = return_after_blind(args.mapped, args.blind, args.back)
    data = write_edited_sequence(args.out / "data", room, SequenceEdit(order, blind))
    lines = [
        "| recovery | failed frames | longest run | recovered (start / relocalised) "
        "| first tracked back | largest error from there | ATE RMSE |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name in args.settings:
        settings = PRESETS.get(name, tuple(name.split(",")))
        config = synthetic_run_config(args.config, data, *settings)
        run_dir = args.out / f"run-{len(lines) - 2}"
        metrics = run_slam(config, run_dir, overwrite=True).metrics
        lines.append(row(name, run_dir, args.mapped + args.blind, metrics))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
