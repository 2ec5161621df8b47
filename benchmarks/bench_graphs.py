"""Eager against CUDA graphs (``compute.cuda_graphs``): milliseconds per tracking frame
and per mapping call, and how far apart the two paths' results are.

The workload is bench_core's (synthetic Replica-sized views, the paper's field over
room0's bound, the paper's settings): a tracking frame of ``tracking.render.iterations``
iterations and a mapping call of ``mapping.iterations`` iterations over a window of
bench_core's 10 keyframes (all poses but the oldest refined), run by the eager path
(:func:`eslam.slam.tracking.render.track_frame`,
:func:`eslam.slam.mapping.mapper.map_window`) and by ``compute.cuda_graphs: auto``
(:class:`eslam.slam.cuda_graphs.GraphedRenderTracker`,
:class:`eslam.slam.cuda_graphs.WindowMapper`), each on its own copy of the field and its
own generator seeded alike.

1. Agreement: one frame and one call of each from the same state; the largest
   difference of the tracked pose, of the window's poses and of any field parameter
   (the graphed path's first frame and call include its capture: their times are
   reported apart).
2. Speed: median and 90th percentile of ``--repeats`` timed frames and calls after
   ``--warmup`` untimed ones, eager and graphed interleaved (bench_core's
   ``time_interleaved``, synchronised around each on CUDA).

Where graphs cannot run (a CPU or MPS device) both columns run the eager steps and the
section says so. The markdown is printed and, unless ``--no-append``, appended to
docs/benchmarks.md (or ``--docs PATH``).

Usage:
    python benchmarks/bench_graphs.py [--device cuda] [--repeats N] [--warmup N]
        [--threads N] [--no-append] [--docs PATH] [--note TEXT]
"""

from __future__ import annotations

import argparse
import copy
import time
from collections.abc import Callable

import torch
from _machine import (
    add_timing_arguments,
    check_timing_arguments,
    run_timing_benchmark,
    section_head,
)
from bench_core import SEED, WINDOW, Stats, build_field, synchronize, time_interleaved, workload

from eslam.slam.cuda_graphs import GraphedRenderTracker, WindowMapper, use_cuda_graphs
from eslam.slam.mapping.mapper import MappingSettings, map_window, mapping_schedule
from eslam.slam.tracking.render import TrackingSettings, track_frame


def timed(call: Callable[[], object], device: torch.device) -> tuple[object, float]:
    """``call()`` and its wall time in milliseconds (synchronised on CUDA)."""
    synchronize(device)
    start = time.perf_counter()
    result = call()
    synchronize(device)
    return result, (time.perf_counter() - start) * 1e3


def largest_difference(a: list[torch.Tensor], b: list[torch.Tensor]) -> float:
    """max |a - b| over pairs of tensors."""
    return max(float((x.detach() - y.detach()).abs().max()) for x, y in zip(a, b, strict=True))


def run(device: torch.device, warmup: int, repeats: int) -> dict[str, object]:
    """Agreement and timings of the eager and graphed paths (module doc)."""
    work = workload(device)
    config = work.config
    eager_field = build_field(config, config.field.plane_sampling, device)
    graph_field = copy.deepcopy(eager_field)
    tracking = TrackingSettings(config.tracking.render, config.render, config.loss)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    tracker = GraphedRenderTracker(tracking, mode="auto")
    mapper = WindowMapper(mapping, "auto")
    schedule = mapping_schedule(config.mapping, first=False)
    optimise = [k > 0 for k in range(WINDOW)]
    view, pose = work.views[0], work.poses[0]
    eager_generator = torch.Generator(device=device).manual_seed(SEED)
    graph_generator = torch.Generator(device=device).manual_seed(SEED)

    def eager_frame() -> object:
        return track_frame(eager_field, view, pose, tracking, eager_generator)

    def graph_frame() -> object:
        return tracker.track(graph_field, view, pose, graph_generator)

    def eager_call() -> object:
        return map_window(
            eager_field, work.views, work.poses, optimise, mapping, schedule, eager_generator
        )

    def graph_call() -> object:
        return mapper.map(graph_field, work.views, work.poses, optimise, schedule, graph_generator)

    eager_tracked, _ = timed(eager_frame, device)
    graph_tracked, first_frame_ms = timed(graph_frame, device)
    eager_mapped, _ = timed(eager_call, device)
    graph_mapped, first_call_ms = timed(graph_call, device)
    agreement = {
        "tracked pose": largest_difference([graph_tracked.pose], [eager_tracked.pose]),
        "window poses": largest_difference([graph_mapped.poses], [eager_mapped.poses]),
        "field parameters": largest_difference(
            list(graph_field.parameters()), list(eager_field.parameters())
        ),
    }
    steps = {
        "tracking eager": eager_frame,
        "tracking graphs": graph_frame,
        "mapping eager": eager_call,
        "mapping graphs": graph_call,
    }
    return {
        "graphs": use_cuda_graphs("auto", device),
        "agreement": agreement,
        "first": {"tracking": first_frame_ms, "mapping": first_call_ms},
        "times": time_interleaved(steps, warmup, repeats, device),
        "captures": {"tracking": tracker.graphs.captures, "mapping": mapper.captures},
        "iterations": {
            "tracking": config.tracking.render.iterations,
            "mapping": schedule.iterations,
        },
    }


def report(results: dict, device: torch.device, args: argparse.Namespace, command: str, load):
    """The markdown section (heading, machine, command, tables)."""
    graphs = results["graphs"]
    note = args.note or None
    if not graphs:
        fallback = f"no CUDA graphs on {device.type}: both columns run the eager steps"
        note = fallback if note is None else f"{note}; {fallback}"
    lines = section_head(
        "bench_graphs",
        device,
        load,
        command,
        f"bench_core's synthetic workload (Replica-sized views, room0's bound, paper settings),"
        f" {args.warmup} warm-up + {args.repeats} timed frames and calls, interleaved",
        note=note,
    )
    times: dict[str, Stats] = results["times"]
    iterations = results["iterations"]
    lines += [
        "",
        "| work | eager ms (median / p90) | graphs ms (median / p90) | speed-up "
        "| first graphed (with capture) ms | captures |",
        "|---|---|---|---|---|---|",
    ]
    for name, label in (
        ("tracking", f"tracking frame ({iterations['tracking']} iterations)"),
        ("mapping", f"mapping call ({iterations['mapping']} iterations, window {WINDOW})"),
    ):
        eager, graph = times[f"{name} eager"], times[f"{name} graphs"]
        lines.append(
            f"| {label} | {eager.median:.1f} / {eager.p90:.1f} | {graph.median:.1f} / "
            f"{graph.p90:.1f} | {eager.median / graph.median:.2f}x | "
            f"{results['first'][name]:.0f} | {results['captures'][name]} |"
        )
    lines += ["", "Largest difference after one frame and one call from the same state:", ""]
    lines += [f"- {what}: {value:.2e}" for what, value in results["agreement"].items()]
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="eager against CUDA graphs: ms per tracking frame and mapping call"
    )
    add_timing_arguments(parser, repeats=10, warmup=2)
    args = parser.parse_args(argv)
    check_timing_arguments(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    run_timing_benchmark("benchmarks/bench_graphs.py", argv, parse_args(argv), run, report)


if __name__ == "__main__":
    main()
