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
- ``demo``: the synthetic demo scene (``eslam demo``'s, written under ``--out`` once)
  with the demo's CPU preset.
- ``corridor``: the demo's camera and preset for 240 frames in the empty synthetic
  corridor (``eslam synth --scene corridor``): walls, floor and ceiling only; from about
  frame 90 the camera sees one side wall and the floor, and the geometry leaves the
  motion along the corridor open.

``--methods render sdf hybrid`` runs every case once per tracker (``tracking.method``);
the table then also gives the Sim(3) scale, the relative pose error between consecutive
frames (RMSE of translation and rotation, metrics.json's ``rpe_*``), the median tracking
time per frame after
frame 0, frames per second (frames / wall time of the run) and the frames the tracker
reported as failed.

Writes a markdown section (machine, command, table) to docs/benchmarks.md unless
``--no-append``. Meshing is off: these runs measure tracking and mapping.

    python benchmarks/real_data.py --device cpu --cases redkitchen-cpu room0-cpu
    python benchmarks/real_data.py --device cuda            # every case
    python benchmarks/real_data.py --cases demo --methods render sdf hybrid
    python benchmarks/real_data.py --cases room0-paper --methods hybrid mapping.first_iterations=60

Trailing ``key=value`` overrides apply to every case (after the case's own settings).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from dataclasses import dataclass, replace
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
    publish,
    section_head,
)

from eslam.config import load_config
from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.io.checkpoint import load_checkpoint
from eslam.slam.session import RunResult, run_slam
from eslam.slam.tracking.trackers import TRACKERS

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
        synthetic: the synthetic scene (``eslam.synthetic.SCENES``) written under
            ``--out`` instead of a sequence under the data root, or None.
    """

    name: str
    config: str
    data: str
    frames: int | None
    budgeted: bool = False
    synthetic: str | None = None


CASES = (
    Case("redkitchen-cpu", "sevenscenes/redkitchen_cpu.yaml", "7scenes-redkitchen", 400),
    Case("redkitchen-scannet", "sevenscenes/redkitchen.yaml", "7scenes-redkitchen", 400, True),
    Case("room0-cpu", "replica/room0_cpu.yaml", "replica-room0", None),
    Case("room0-paper", "replica/room0.yaml", "replica-room0", None),
    Case("demo", "demo.yaml", "", None, synthetic="room"),
    Case("corridor", "demo.yaml", "", 240, synthetic="corridor"),
)
"""Every case; ``demo`` reads the synthetic demo scene written under ``--out``, and
``corridor`` the demo's camera and settings for 240 frames in the empty synthetic
corridor (``eslam.synthetic.corridor``): the camera's yaw turns by 120 degrees, and
from about frame 90 on it sees one side wall and the floor only, views whose geometry
leaves the motion along the corridor open."""


def synthetic_overrides(out: Path, case: Case) -> list[str]:
    """data.path and scene.bound of ``case``'s synthetic scene (written to
    ``out/NAME-data`` once): the demo's camera in ``case.synthetic``, with
    ``case.frames`` frames (the demo's 60 when None)."""
    from eslam.synthetic import read_synthetic_bound, write_synthetic_sequence
    from eslam.workflows.demo import DEMO_SCENE

    frames = case.frames or DEMO_SCENE.frames
    data = out / f"{case.name}-data"
    if not (data / "synth.json").is_file():
        synth = replace(DEMO_SCENE, scene=case.synthetic, frames=frames)
        write_synthetic_sequence(data, synth, overwrite=True)
    return [f"data.path={data}", f"scene.bound={read_synthetic_bound(data)}"]


@dataclass(frozen=True)
class Row:
    case: Case
    method: str
    result: RunResult
    wall_s: float


def run_case(case: Case, method: str, args: argparse.Namespace, repeat: int = 0) -> Row:
    """Run ``case`` with ``method`` into ``args.out/case.name[-method][-repeat]`` (a
    method named twice in ``--methods`` runs twice, into two folders); return its
    metrics."""
    name = case.name if args.methods is None else f"{case.name}-{method}"
    out = args.out / (f"{name}-{repeat + 1}" if repeat else name)
    data = (
        synthetic_overrides(args.out, case)
        if case.synthetic is not None
        else [f"data.path={args.data_root / case.data}"]
    )
    overrides = [
        *data,
        f"tracking.method={method}",
        f"device={args.device}",
        f"threads={args.threads}",
        "output.progress=false",
        "output.mesh=false",
        *args.overrides,
    ]
    limits = [f for f in (case.frames, args.max_frames) if f is not None]
    frames = min(limits) if limits else None
    if frames is not None:
        overrides.append(f"data.max_frames={frames}")
    config = load_config(CONFIGS / case.config, overrides)
    start = time.perf_counter()
    if not case.budgeted:
        result = run_slam(config, out, overwrite=True)
        return Row(case, method, result, time.perf_counter() - start)
    probe = run_slam(config, out, stop_after=args.probe, overwrite=True)
    timings = json.loads((out / "timings.json").read_text())
    recent = timings["tracking_s"][1:] + timings["mapping_s"][1:]
    per_frame = sum(recent) / max(len(timings["tracking_s"]) - 1, 1)
    left = args.budget_min * 60.0 - (time.perf_counter() - start)
    target = probe.metrics["frames"] + max(0, int(left / max(per_frame, 1e-3)))
    total = frames or target
    result = run_slam(config, out, resume=True, stop_after=min(total, target))
    return Row(case, method, result, time.perf_counter() - start)


def run_methods(case: Case, methods: list[str], args: argparse.Namespace) -> list[Row]:
    """Run ``case`` once per entry of ``methods``, in order; a tracker named again runs
    into a folder of its own (``-2``, ``-3``...)."""
    rows = []
    for index, method in enumerate(methods):
        row = run_case(case, method, args, repeat=methods[:index].count(method))
        print(f"{case.name} {method}: {row.result.metrics}", flush=True)
        rows.append(row)
    return rows


def tracker_figures(row: Row) -> tuple[float, float, float, float]:
    """Sim(3) scale of the trajectory, median tracking seconds per frame after frame 0,
    frames per second (frames / wall time of the run) and the seconds to the first
    tracked pose (frame 0's tracking and mapping, then frame 1's tracking)."""
    run_dir = row.result.run_dir
    timings = json.loads((run_dir / "timings.json").read_text())
    tracking = timings["tracking_s"][1:] or [float("nan")]
    first_pose = (
        sum(timings["tracking_s"][:2]) + timings["mapping_s"][0]
        if len(timings["tracking_s"]) > 1
        else float("nan")
    )
    scale = float("nan")
    saved = load_checkpoint(run_dir / "map.pt")["trajectory"]
    if saved["gt"] is not None and len(saved["poses"]) >= 3:  # Sim(3) needs 3 positions
        poses, gt = saved["poses"].double().numpy(), saved["gt"].double().numpy()
        scale = absolute_trajectory_error(poses, gt, with_scale=True).alignment.scale
    fps = row.result.metrics["frames"] / max(row.wall_s, 1e-9)
    return scale, statistics.median(tracking), fps, first_pose


def table(rows: list[Row], methods: bool) -> str:
    if methods:
        lines = [
            "| case | tracker | frames | ATE RMSE (cm) | Sim(3) scale | RPE (mm, deg) "
            "| tracking (s/frame) | FPS | to first pose (s) | failed frames "
            "| degenerate frames | peak memory (MB) |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for row in rows:
            m = row.result.metrics
            scale, tracking, fps, first_pose = tracker_figures(row)
            lines.append(
                f"| {row.case.name} | {row.method} | {m['frames']} "
                f"| {m.get('ate_rmse_cm', float('nan')):.2f} | {scale:.4f} "
                f"| {m.get('rpe_translation_rmse_mm', float('nan')):.2f}, "
                f"{m.get('rpe_rotation_rmse_deg', float('nan')):.3f} | {tracking:.3f} "
                f"| {fps:.3f} | {first_pose:.1f} | {m.get('tracking_failures', '-')} "
                f"| {m.get('tracking_degenerate_frames', '-')} | {m['peak_memory_mb']:.0f} |"
            )
        return "\n".join(lines) + "\n"
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
    parser.add_argument(
        "--methods",
        nargs="+",
        choices=list(TRACKERS.names()),
        help="run each case once per tracker (default: the config's tracker, once)",
    )
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("--note", default="")
    parser.add_argument(
        "overrides", nargs="*", metavar="key=value", help="config overrides for every case"
    )
    args = parser.parse_intermixed_args(argv)  # overrides may come before options
    check_device(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)  # run_slam leaves torch's threads alone (the CLI sets them)
    device = torch.device(args.device)
    command = command_line("benchmarks/real_data.py", argv)
    load_start = load_average()
    rows = []
    for case in CASES:
        if case.name not in args.cases:
            continue
        configured = load_config(CONFIGS / case.config).tracking.method
        rows.extend(run_methods(case, args.methods or [configured], args))
    lines = section_head(
        "real_data",
        device,
        (load_start, load_average()),
        command,
        "../shared/data (7-Scenes redkitchen frames 0-399, Replica room0 frames 0-19) "
        "or the synthetic demo scene or corridor; no mesh; "
        "FPT = tracking + mapping wall time / frames",
        ("overrides on every case", args.overrides),
        args.note,
    )
    section = "\n".join([*lines, "", table(rows, args.methods is not None)])
    publish(section, args.docs, args.no_append)


if __name__ == "__main__":
    main()
