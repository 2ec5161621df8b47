"""Full runs on the real sequences under ../shared/data: ATE, frame time, peak memory.

Cases (each a run folder under ``--out``):

- ``redkitchen-cpu``: 7-Scenes redkitchen frames 0-399, CPU preset
  (configs/sevenscenes/redkitchen_cpu.yaml), no hand-set bound.
- ``redkitchen-scannet``: the same frames with the paper's ScanNet settings
  (configs/sevenscenes/redkitchen.yaml), as many frames as fit in ``--budget-min``
  minutes: a probe of ``--probe`` frames measures the frame time, then the run is
  resumed (``eslam resume`` semantics) up to the frame count that fits.
- ``room0-cpu`` and ``room0-paper``: Replica room0 frames 0-19 with the CPU preset and
  with the paper's settings.

Writes a markdown section (machine, command, table) to docs/benchmarks.md unless
``--no-append``. Meshing is off: these runs measure tracking and mapping.

    python benchmarks/real_data.py --device cpu --cases redkitchen-cpu room0-cpu
    python benchmarks/real_data.py --device cuda            # every case
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import (
    DEFAULT_DOCS,
    REPO,
    add_device_argument,
    check_device,
    command_line,
    load_average,
    machine_lines,
    publish,
)

from eslam.config import load_config
from eslam.slam.loop import RunResult, run_slam

CONFIGS = REPO / "eslam" / "configs"


@dataclass(frozen=True)
class Case:
    """One benchmark run.

    Attributes:
        name: label of the row and of the run folder.
        config: config file, relative to eslam/configs.
        data: sequence folder, relative to the data root.
        frames: frames to run (from frame 0), or None for all.
        budgeted: stop at the frame count that fits in the time budget.
    """

    name: str
    config: str
    data: str
    frames: int | None
    budgeted: bool = False


CASES = (
    Case("redkitchen-cpu", "sevenscenes/redkitchen_cpu.yaml", "7scenes-redkitchen", 400),
    Case("redkitchen-scannet", "sevenscenes/redkitchen.yaml", "7scenes-redkitchen", 400, True),
    Case("room0-cpu", "replica/room0_cpu.yaml", "replica-room0", None),
    Case("room0-paper", "replica/room0.yaml", "replica-room0", None),
)


@dataclass(frozen=True)
class Row:
    case: Case
    result: RunResult
    wall_s: float


def run_case(case: Case, args: argparse.Namespace) -> Row:
    """Run ``case`` into ``args.out/case.name`` and return its metrics."""
    out = args.out / case.name
    overrides = [
        f"data.path={args.data_root / case.data}",
        f"device={args.device}",
        f"threads={args.threads}",
        "output.progress=false",
        "output.mesh=false",
    ]
    limits = [f for f in (case.frames, args.max_frames) if f is not None]
    frames = min(limits) if limits else None
    if frames is not None:
        overrides.append(f"data.max_frames={frames}")
    config = load_config(CONFIGS / case.config, overrides)
    start = time.perf_counter()
    if not case.budgeted:
        result = run_slam(config, out, overwrite=True)
        return Row(case, result, time.perf_counter() - start)
    probe = run_slam(config, out, stop_after=args.probe, overwrite=True)
    timings = json.loads((out / "timings.json").read_text())
    recent = timings["tracking_s"][1:] + timings["mapping_s"][1:]
    per_frame = sum(recent) / max(len(timings["tracking_s"]) - 1, 1)
    left = args.budget_min * 60.0 - (time.perf_counter() - start)
    target = probe.metrics["frames"] + max(0, int(left / max(per_frame, 1e-3)))
    total = frames or target
    result = run_slam(config, out, resume=True, stop_after=min(total, target))
    return Row(case, result, time.perf_counter() - start)


def table(rows: list[Row]) -> str:
    lines = [
        "| case | config | frames | ATE RMSE (cm) | ATE mean (cm) | FPT (s) | peak memory (MB) "
        "| wall (min) |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        m = row.result.metrics
        ate = m.get("ate_rmse_cm", float("nan"))
        mean = m.get("ate_mean_cm", float("nan"))
        lines.append(
            f"| {row.case.name} | `configs/{row.case.config}` | {m['frames']} | {ate:.2f} "
            f"| {mean:.2f} | {m['fpt_s']:.3f} | {m['peak_memory_mb']:.0f} "
            f"| {row.wall_s / 60:.1f} |"
        )
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    default_root = os.environ.get("ESLAM_TEST_DATA", str(REPO.parent / "shared" / "data"))
    parser.add_argument("--data-root", type=Path, default=Path(default_root))
    add_device_argument(parser)
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    parser.add_argument("--out", type=Path, default=Path("runs/real_data"))
    parser.add_argument(
        "--cases", nargs="+", choices=[c.name for c in CASES], default=[c.name for c in CASES]
    )
    parser.add_argument("--budget-min", type=float, default=30.0, help="budgeted case limit")
    parser.add_argument("--probe", type=int, default=20, help="frames timed before the budget")
    parser.add_argument("--max-frames", type=int, help="cap every case (smoke tests)")
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("--note", default="")
    args = parser.parse_args(argv)
    check_device(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    device = torch.device(args.device)
    command = command_line("benchmarks/real_data.py", argv)
    load_start = load_average()
    rows = []
    for case in CASES:
        if case.name in args.cases:
            row = run_case(case, args)
            print(f"{case.name}: {row.result.metrics}", flush=True)
            rows.append(row)
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## real_data, {now}, {device.type}",
        "",
        *machine_lines(device, (load_start, load_average())),
        f"- command: `{command}`",
        "- data: ../shared/data (7-Scenes redkitchen frames 0-399, Replica room0 frames 0-19); "
        "no mesh; FPT = tracking + mapping wall time / frames",
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    section = "\n".join([*lines, "", table(rows)])
    publish(section, args.docs, args.no_append)


if __name__ == "__main__":
    main()
