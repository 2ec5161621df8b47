"""The first mapping call: held-out depth L1 and time per schedule, on a synthetic scene.

For each schedule (iterations, learning-rate factor, rays per step, cosine decay of the
learning rates to a final fraction, and optionally a TSDF warm start before them,
:mod:`eslam.slam.mapping.warm_start`) a fresh field (seeded) is fit to frame 0 of the
demo's synthetic room with its ground-truth pose, exactly as the run loop's first
mapping call does (:func:`eslam.slam.mapping.mapper.map_window`). The quality figures
(:func:`eslam.render.held_out.held_out_errors`) are taken over every ``--pixel-step``-th
valid pixel of frames ``--held-out`` (never mapped) whose surface point frame 0 observed
(``--all-pixels`` scores them all): the held-out depth L1 (mean |surface depth - true
depth| at the true poses, the surface found where the TSDF crosses zero along each
pixel's ray, as a mesh would show it) and the surface SDF (mean |T s(p)| at the
measured points, the SDF tracker's residual at the true pose). Time is the wall
time of the mapping call and its CPU time (the process's; with ``--threads 1`` the
work done, which a loaded machine inflates less than the wall time).

    python benchmarks/first_frame.py                          # the default schedules
    python benchmarks/first_frame.py --schedule fast:150:5:4000:0.1 --config demo.yaml
    python benchmarks/first_frame.py --schedule warm:30:2:0:1:400:4000:0.25:20

Schedules are NAME:ITERATIONS:LR_FACTOR:RAYS:DECAY (RAYS 0 = the config's mapping.rays),
optionally followed by :WARM_STEPS:WARM_POINTS[:WARM_BAND[:WARM_LR_FACTOR]] for a TSDF
warm start (band share 0.25 and rate factor 20 unless given).
Prints a markdown table and, unless ``--no-append``, appends it to docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import (
    DEFAULT_DOCS,
    REPO,
    command_line,
    load_average,
    machine_lines,
    publish,
)

from eslam.config import load_config
from eslam.render.held_out import HeldOutErrors, held_out_errors
from eslam.render.rays import camera_directions
from eslam.slam.mapping.mapper import MappingSchedule, MappingSettings, map_window
from eslam.slam.mapping.warm_start import WarmStart
from eslam.slam.state import new_field
from eslam.slam.views import make_view
from eslam.synthetic import SynthConfig, build_scene, generate_sequence, scene_bound
from eslam.workflows.demo import DEMO_SCENE

DEFAULT_SCHEDULES = (
    "release:1000:5:0:1",
    "cpu-preset:300:5:0:1",
    "short:150:5:0:1",
    "short-decay:150:5:0:0.1",
    "short-wide-decay:150:5:8000:0.1",
    "tiny-wide-decay:60:5:8000:0.1",
    "warm-only:0:5:0:1:400:4000",
    "cpu-preset:30:2:0:1:400:4000",
)


@dataclass(frozen=True)
class Schedule:
    name: str
    iterations: int
    lr_factor: float
    rays: int
    decay: float
    warm_steps: int = 0
    warm_points: int = 0
    warm_band: float = 0.25
    warm_factor: float = 20.0

    @classmethod
    def parse(cls, text: str) -> Schedule:
        name, iterations, factor, rays, decay, *warm = text.split(":")
        numbers = [int(warm[0]), int(warm[1]), *map(float, warm[2:])] if warm else []
        return cls(name, int(iterations), float(factor), int(rays), float(decay), *numbers)

    def warm_start(self) -> WarmStart | None:
        if self.warm_steps == 0:
            return None
        return WarmStart(self.warm_steps, self.warm_points, self.warm_band, self.warm_factor)


def run(args: argparse.Namespace) -> list[tuple[Schedule, float, float, HeldOutErrors]]:
    config = load_config(REPO / "eslam" / "configs" / args.config, args.overrides)
    scene = SynthConfig(
        frames=max(args.held_out) + 1, width=DEMO_SCENE.width, height=DEMO_SCENE.height, seed=0
    )
    frames = list(generate_sequence(scene))
    bound = torch.tensor(scene_bound(build_scene(scene.scene, scene.seed)))
    first = frames[0]
    view = make_view(
        torch.from_numpy(first.rgb).float() / 255.0,
        torch.from_numpy(first.depth),
        camera_directions(first.intrinsics),
    )
    pose = torch.from_numpy(first.pose_gt).float()[None]
    settings = MappingSettings(config.mapping, config.render, config.loss)
    rows = []
    for schedule in args.schedules:
        field = new_field(config, bound, torch.device("cpu"))
        plan = MappingSchedule(
            schedule.iterations,
            schedule.lr_factor,
            schedule.rays or config.mapping.rays,
            schedule.decay,
            schedule.warm_start(),
        )
        generator = torch.Generator().manual_seed(config.seed)
        start, cpu_start = time.perf_counter(), time.process_time()
        map_window(field, [view], pose, [False], settings, plan, generator)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
        field.requires_grad_(False)
        errors = held_out_errors(
            field,
            [frames[i] for i in args.held_out],
            observed_by=None if args.all_pixels else first,
            pixel_step=args.pixel_step,
        )
        rows.append((schedule, seconds, cpu, errors))
        print(
            f"{schedule.name}: {seconds:.1f} s ({cpu:.1f} s CPU), "
            f"depth L1 {100 * errors.depth_l1_m:.3f} cm, "
            f"surface SDF {100 * errors.surface_sdf_m:.3f} cm",
            flush=True,
        )
    return rows


def table(rows: list[tuple[Schedule, float, float, HeldOutErrors]], config_rays: int) -> str:
    reference = rows[0]
    lines = [
        "| schedule | TSDF warm start (steps x points, band, lr factor) | iterations "
        "| lr factor | rays | lr decay to | time (s) | CPU time (s) | CPU vs "
        f"{reference[0].name} | held-out depth L1 (cm) | vs {reference[0].name} "
        "| surface SDF (cm) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for schedule, seconds, cpu, errors in rows:
        l1 = errors.depth_l1_m
        warm = (
            f"{schedule.warm_steps} x {schedule.warm_points}, {schedule.warm_band:g}, "
            f"{schedule.warm_factor:g}"
            if schedule.warm_steps
            else "-"
        )
        lines.append(
            f"| {schedule.name} | {warm} | {schedule.iterations} | {schedule.lr_factor:g} "
            f"| {schedule.rays or config_rays} | {schedule.decay:g} | {seconds:.1f} "
            f"| {cpu:.1f} | {cpu / reference[2]:.3f} "
            f"| {100 * l1:.3f} | {l1 / reference[3].depth_l1_m:.2f}x "
            f"| {100 * errors.surface_sdf_m:.3f} |"
        )
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", default="demo.yaml", help="config under eslam/configs")
    parser.add_argument(
        "--schedule",
        action="append",
        help="NAME:ITER:FACTOR:RAYS:DECAY[:WARM_STEPS:WARM_POINTS[:WARM_BAND[:WARM_FACTOR]]]",
    )
    parser.add_argument("--held-out", type=int, nargs="+", default=[3, 6, 9])
    parser.add_argument("--pixel-step", type=int, default=7)
    parser.add_argument(
        "--all-pixels",
        action="store_true",
        help="score every valid held-out pixel, also surfaces frame 0 never saw",
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("--note", default="")
    parser.add_argument("overrides", nargs="*", help="config overrides key=value")
    args = parser.parse_intermixed_args(argv)  # overrides may come before options
    args.schedules = [Schedule.parse(s) for s in (args.schedule or DEFAULT_SCHEDULES)]
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    command = command_line("benchmarks/first_frame.py", argv)
    load_start = load_average()
    rows = run(args)
    config = load_config(REPO / "eslam" / "configs" / args.config, args.overrides)
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## first_frame, {now}, cpu",
        "",
        *machine_lines(torch.device("cpu"), (load_start, load_average())),
        f"- command: `{command}`",
        f"- workload: frame 0 of the demo's synthetic room ({DEMO_SCENE.width}x"
        f"{DEMO_SCENE.height}), config `{args.config}` {' '.join(args.overrides)}; "
        f"held-out frames {args.held_out}, every {args.pixel_step}th valid pixel"
        + (" (all of them)" if args.all_pixels else " that frame 0 observed"),
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    publish("\n".join([*lines, "", table(rows, config.mapping.rays)]), args.docs, args.no_append)


if __name__ == "__main__":
    main()
