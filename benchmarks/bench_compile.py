"""Is ``torch.compile`` faster per stage? Eager against compiled, at the paper's Replica settings.

Issue 12 asks to use ``torch.compile`` on the CPU only where a benchmark shows it is
faster, measured per stage. This script times, interleaved (one iteration of each in
turn, so a change of load hits both alike), the eager and the ``torch.compile``d
(default inductor backend) forward + backward of:

* decoders: both MLP decoders on the plane features of 80,000 points;
* field query: plane sampling + decoders at 80,000 points (:meth:`SceneField.query`);
* tracking loss: :func:`eslam.slam.tracking.render.tracking_loss`, 2000 rays (the iteration
  without its ray draw and Adam step, which stay outside any compiled graph);
* mapping loss: :func:`eslam.slam.mapping.mapper.mapping_loss`, 4000 rays over 10 views.

It reuses bench_core's workload (Replica-sized synthetic views, room0's bound, the
default plane sampling) and prints the first compiled call's time (the compilation) as
well. Run from the repository root:

    python benchmarks/bench_compile.py --device cpu --threads 2

and the section is appended to docs/benchmarks.md (``--no-append`` to print only).
"""

from __future__ import annotations

import argparse
import datetime
import time
from collections.abc import Callable

import torch
from _machine import (
    add_timing_arguments,
    check_timing_arguments,
    machine_lines,
    run_timing_benchmark,
)
from bench_core import SEED, Stats, build_field, synchronize, time_interleaved, workload

from eslam.field.planes import normalize_points
from eslam.field.scene_field import SceneField
from eslam.slam.mapping.mapper import MappingSettings, WindowPoses, mapping_loss
from eslam.slam.tracking.render import PoseVariables, TrackingSettings, tracking_loss
from eslam.slam.views import draw_rays

Step = Callable[[], None]
"""One forward + backward of a stage (gradients set to None first)."""


def stage_functions(field: SceneField, device: torch.device) -> dict[str, Callable]:
    """The forward of each stage as a function of tensors (what torch.compile traces),
    with the inputs bound; each returns a 0-d value to backpropagate."""
    work = workload(device)
    config = work.config
    points = work.points
    with torch.no_grad():
        geometry, colour = field.plane_features(normalize_points(points, field.bound))
    geometry.requires_grad_(True)
    colour.requires_grad_(True)
    generator = torch.Generator(device=device).manual_seed(SEED)
    tracking = TrackingSettings(config.tracking.render, config.render, config.loss)
    variables = PoseVariables.from_pose(work.poses[0])
    tracking_draws = draw_rays(1, tracking.tracking.rays, config.render, generator, device)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    window = WindowPoses.create(work.poses, [k > 0 for k in range(len(work.views))])
    per_view = config.mapping.rays // len(work.views)
    mapping_draws = draw_rays(len(work.views), per_view, config.render, generator, device)

    def decoders(g: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        return field.geometry_decoder(g).sum() + field.appearance_decoder(c).sum()

    def query(p: torch.Tensor) -> torch.Tensor:
        out = field.query(p)
        return out.sdf.sum() + out.rgb.sum()

    def track(v: PoseVariables) -> torch.Tensor:
        return tracking_loss(field, work.views[0], v, tracking_draws, tracking)[0]

    def map_(w: WindowPoses) -> torch.Tensor:
        return mapping_loss(field, work.views, w, mapping_draws, mapping)

    return {
        "decoders, 80,000 points": (decoders, (geometry, colour)),
        "field query, 80,000 points": (query, (points,)),
        "tracking loss, 2000 rays": (track, (variables,)),
        "mapping loss, 4000 rays / 10 views": (map_, (window,)),
    }


def forward_backward(function: Callable, inputs: tuple, field: SceneField) -> Step:
    """A step: clear the gradients, run ``function(*inputs)``, backpropagate."""

    def step() -> None:
        field.zero_grad(set_to_none=True)
        function(*inputs).backward()

    return step


def timed_first_call(step: Step, device: torch.device) -> float:
    """Seconds of the first call (for a compiled step: tracing and code generation)."""
    synchronize(device)
    start = time.perf_counter()
    step()
    synchronize(device)
    return time.perf_counter() - start


def run(device: torch.device, warmup: int, repeats: int) -> list[tuple[str, Stats, Stats, float]]:
    """Per stage: eager and compiled timings, interleaved, and the compilation's seconds."""
    field = build_field(workload(device).config, "fused", device)
    rows = []
    for name, (function, inputs) in stage_functions(field, device).items():
        torch._dynamo.reset()
        eager = forward_backward(function, inputs, field)
        compiled = forward_backward(torch.compile(function), inputs, field)
        tracking = name.startswith("tracking")
        if tracking:  # the tracker differentiates the pose only
            field.requires_grad_(False)
        compile_s = timed_first_call(compiled, device)
        stats = time_interleaved({"eager": eager, "compiled": compiled}, warmup, repeats, device)
        if tracking:
            field.requires_grad_(True)
        rows.append((name, stats["eager"], stats["compiled"], compile_s))
        print(f"{name}: eager {stats['eager']}, compiled {stats['compiled']}", flush=True)
    return rows


def report(
    rows: list[tuple[str, Stats, Stats, float]],
    device: torch.device,
    args: argparse.Namespace,
    command: str,
    load: tuple[float | None, float | None],
) -> str:
    """The markdown section: heading, machine, command, the table."""
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## bench_compile, {now}, {device.type}",
        "",
        *machine_lines(device, load),
        f"- command: `{command}`",
        "- workload: bench_core's (paper Replica settings, 1200x680 synthetic views, "
        f"fused plane sampling); {args.warmup} warm-up + {args.repeats} timed iterations "
        "each, eager and compiled interleaved; compiled = torch.compile, inductor backend",
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    table = [
        "| forward + backward (ms) | eager median | eager p90 | compiled median "
        "| compiled p90 | eager / compiled | first compiled call (s) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, eager, compiled, compile_s in rows:
        table.append(
            f"| {name} | {eager.median:.1f} | {eager.p90:.1f} | {compiled.median:.1f} "
            f"| {compiled.p90:.1f} | {eager.median / compiled.median:.2f}x | {compile_s:.1f} |"
        )
    return "\n".join([*lines, "", *table])


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_timing_arguments(parser, repeats=10, warmup=2)
    args = parser.parse_args(argv)
    check_timing_arguments(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    run_timing_benchmark("benchmarks/bench_compile.py", argv, parse_args(argv), run, report)


if __name__ == "__main__":
    main()
