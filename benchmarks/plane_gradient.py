"""The fused plane sampling's gradient into the planes on the CPU: the sorted sum (the
CPU's path) against the 12 scattered adds (the GPU's path, and the CPU's until the
sorted sum), in one mapping iteration and in one field query.

:func:`eslam.field.fused_sampling._plane_gradient_sorted` sorts the 12 N look-ups by
row and sums each row's terms as one bag of an ``F.embedding_bag``;
:func:`~eslam.field.fused_sampling._plane_gradient_scattered` adds the weighted
gradients with one ``index_add_`` per look-up. Both are timed interleaved (one
iteration of each in turn, the scattered one swapped in for the op's backward with
``unittest.mock``), so their ratio holds on a loaded machine:

1. one mapping iteration (:func:`eslam.slam.mapping.mapper.mapping_step` through
   :func:`bench_core.mapping_iteration`) at ``--config``'s mapping settings (rays,
   window, samples), the field over ``--bound`` at the config's resolutions, on
   synthetic views (:func:`bench_core.synthetic_views`) from seeded random poses;
2. one field query (TSDF and colour at mapping's points: rays x samples, uniform in the
   bound), forward and backward into the planes and decoders.

    python benchmarks/plane_gradient.py [--config tum/tum_cpu] [--bound JSON]
        [--repeats 10] [--warmup 2] [--threads 1] [--no-append] [--docs PATH]

The table is printed and, unless ``--no-append``, appended to docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
from unittest import mock

import torch
from _machine import (
    add_timing_arguments,
    check_timing_arguments,
    run_timing_benchmark,
    section_head,
)
from bench_core import (
    SEED,
    field_query_step,
    mapping_iteration,
    random_poses,
    synthetic_views,
    time_interleaved,
)

import eslam.field.fused_sampling as fused
from eslam.config import ESLAMConfig, load_config
from eslam.errors import ConfigError
from eslam.field.scene_field import SceneField

FR1_XYZ_BOUND = [[-1.904, 1.615], [-1.777, 0.895], [-0.5, 3.924]]
"""The bound ``tum/tum_cpu`` takes from TUM fr1/xyz's first depth image (its log.txt)."""

VARIANTS = {"sorted": None, "scattered": fused._plane_gradient_scattered}
"""The plane gradient of each timed variant (None: the op's own, the sorted sum on the CPU)."""


def with_variant(step, gradient):
    """``step`` with the fused op's plane gradient replaced by ``gradient`` (None: as is)."""
    if gradient is None:
        return step

    def swapped() -> object:
        with mock.patch.object(fused, "_plane_gradient", gradient):
            return step()

    return swapped


def run(config: ESLAMConfig, bound: torch.Tensor, device, warmup: int, repeats: int):
    """Stats per (benchmark, variant), and the workload's size for the report."""
    torch.manual_seed(SEED)
    field = SceneField(config.field, bound).to(device)
    data = torch.Generator().manual_seed(SEED)
    window = config.mapping.window
    views = synthetic_views(window, config.tracking.border, device, data)
    poses = random_poses(window, bound, data).to(device)
    samples = config.render.samples_stratified + config.render.samples_surface
    count = config.mapping.rays * samples
    low, high = bound[:, 0], bound[:, 1]
    points = (low + (high - low) * torch.rand(count, 3, generator=data)).to(device)
    results = {}
    for name, build in (
        (
            "mapping iteration",
            lambda: mapping_iteration(
                field, views, poses, config, torch.Generator(device).manual_seed(SEED)
            ),
        ),
        ("field query, forward + backward", lambda: field_query_step(field, points)),
    ):
        steps = {variant: with_variant(build(), grad) for variant, grad in VARIANTS.items()}
        results[name] = time_interleaved(steps, warmup, repeats, device)
    size = sum(p.numel() for p in field.plane_parameters())
    return results, {"points": count, "plane parameters": size, "window": window}


def report(outcome, device, args, command: str, loads) -> str:
    """The markdown section: ms per step for each variant and their ratio."""
    results, size = outcome
    lines = section_head(
        "Plane gradient: sorted sum against scattered adds",
        device,
        loads,
        command,
        f"synthetic: {size['window']} views, {size['points']} points per step "
        f"({args.config}'s rays x samples), field over {args.bound} "
        f"({size['plane parameters']:,} plane parameters)",
    )
    lines += [
        "",
        "| step (ms) | sorted median | sorted p90 | scattered median | scattered p90 "
        "| sorted / scattered |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, stats in results.items():
        new, old = stats["sorted"], stats["scattered"]
        lines.append(
            f"| {name} | {new.median:.1f} | {new.p90:.1f} | {old.median:.1f} | "
            f"{old.p90:.1f} | {new.median / old.median:.2f} |"
        )
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="tum/tum_cpu", help="config name or file")
    parser.add_argument(
        "--bound", default=json.dumps(FR1_XYZ_BOUND), help="the field's bound, JSON, m"
    )
    add_timing_arguments(parser, repeats=10, warmup=2)
    args = parser.parse_args(argv)
    check_timing_arguments(parser, args)
    try:
        args.loaded = load_config(args.config)
        args.bound_tensor = torch.tensor(json.loads(args.bound), dtype=torch.float32)
    except ConfigError as error:
        parser.error(str(error))
    except (ValueError, TypeError) as error:
        parser.error(f"--bound: {error}")
    if args.bound_tensor.shape != (3, 2):
        parser.error("--bound: give [[x0, x1], [y0, y1], [z0, z1]] in metres")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    run_timing_benchmark(
        "benchmarks/plane_gradient.py",
        argv,
        args,
        lambda device, warmup, repeats: run(
            args.loaded, args.bound_tensor, device, warmup, repeats
        ),
        report,
    )


if __name__ == "__main__":
    main()
