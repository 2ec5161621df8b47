"""Milliseconds per tracking and mapping iteration at the paper's Replica settings.

One tracking iteration (2000 rays) and one mapping iteration (4000 rays over a window of
10 keyframes), forward + backward + Adam step, for both plane-sampling paths
(``FieldConfig.plane_sampling`` "reference" and "fast"), plus the field query alone
(2000 x 40 points, forward + backward). Every figure is the median and the 90th
percentile of ``--repeats`` timed iterations after ``--warmup`` untimed ones
(``time.perf_counter``, with ``torch.cuda.synchronize()`` around each on CUDA: the
steps themselves never sync).

The workload needs no dataset: the field spans Replica room0's bound as the authors
publish it (so the planes have the paper's sizes, about 6.6 M learnable parameters)
with the paper's FieldConfig, RenderConfig, LossConfig, TrackingConfig and
MappingConfig defaults; the images are synthetic, Replica-sized (1200 x 680, fx = fy =
600) with seeded random depths in [0.5, 4] m and random colours, seen from seeded random
poses inside the bound. The iterations are the run's own step functions,
:func:`eslam.slam.tracking.tracking_step` and :func:`eslam.slam.mapping.mapping_step`
(no copies), with the optimisers the run builds.

The markdown table is printed and, unless ``--no-append``, appended to
docs/benchmarks.md with the date, the machine and the command line.

Usage:
    python benchmarks/bench_core.py [--device cpu|cuda] [--repeats N] [--warmup N]
        [--threads N] [--no-append] [--docs PATH] [--note TEXT]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from _machine import (
    DEFAULT_DOCS,
    add_device_argument,
    check_device,
    command_line,
    load_average,
    machine_lines,
    publish,
)

from eslam.config import ESLAMConfig
from eslam.field.scene_field import SceneField
from eslam.geometry.pose import quaternion_to_matrix
from eslam.render.rays import camera_directions
from eslam.slam.mapping import MappingSettings, WindowPoses, mapping_optimiser, mapping_step
from eslam.slam.tracking import (
    PoseVariables,
    TrackingSettings,
    frozen,
    pose_optimiser,
    tracking_step,
)
from eslam.slam.views import View, make_view
from eslam.types import Intrinsics

ROOM0_BOUND = [[-1.9, 7.9], [-2.2, 4.5], [-2.5, 2.3]]
"""Replica room0's scene bound in the authors' release (configs/Replica/room0.yaml), m."""

CAMERA = Intrinsics(width=1200, height=680, fx=600.0, fy=600.0, cx=599.5, cy=339.5)
"""Replica's camera (the release's replica.yaml)."""

DEPTH_RANGE = (0.5, 4.0)
"""Random per-pixel depths are uniform on this interval, metres."""

WINDOW = 10
"""Keyframes in the mapping window; the oldest pose is fixed, the others are optimised."""

SEED = 0


@dataclasses.dataclass(frozen=True)
class Stats:
    """Median and 90th percentile of a set of timings, milliseconds."""

    median: float
    p90: float

    @classmethod
    def of(cls, times_ms: list[float]) -> Stats:
        values = np.asarray(times_ms, dtype=np.float64)
        return cls(float(np.median(values)), float(np.percentile(values, 90)))


def synchronize(device: torch.device) -> None:
    """Wait for queued GPU work, so wall-clock intervals cover it (no-op on the CPU)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def time_iterations(
    step: Callable[[], object], warmup: int, repeats: int, device: torch.device
) -> Stats:
    """Run ``step`` ``warmup`` times untimed, then ``repeats`` times timed one by one."""
    for _ in range(warmup):
        step()
    synchronize(device)
    times = []
    for _ in range(repeats):
        synchronize(device)
        start = time.perf_counter()
        step()
        synchronize(device)
        times.append((time.perf_counter() - start) * 1e3)
    return Stats.of(times)


def random_poses(count: int, bound: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """(count, 4, 4) camera-to-world poses: uniform random rotations, centres in the
    middle half of ``bound`` along each axis (so most viewed points fall inside it)."""
    quaternions = torch.randn(count, 4, generator=generator, dtype=torch.float64)
    low, high = bound[:, 0].double(), bound[:, 1].double()
    middle, half = (low + high) / 2, (high - low) / 4
    centres = (
        middle + (2 * torch.rand(count, 3, generator=generator, dtype=torch.float64) - 1) * half
    )
    poses = torch.eye(4, dtype=torch.float64).repeat(count, 1, 1)
    poses[:, :3, :3] = quaternion_to_matrix(quaternions)
    poses[:, :3, 3] = centres
    return poses.float()


def synthetic_views(
    count: int, border: int, device: torch.device, generator: torch.Generator
) -> list[View]:
    """``count`` Replica-sized RGB-D images with random depths and colours, as Views."""
    directions = camera_directions(CAMERA, device=device)
    low, high = DEPTH_RANGE
    views = []
    for _ in range(count):
        shape = (CAMERA.height, CAMERA.width)
        depth = low + (high - low) * torch.rand(shape, generator=generator)
        rgb = torch.rand((*shape, 3), generator=generator)
        views.append(make_view(rgb.to(device), depth.to(device), directions, border))
    return views


def build_field(config: ESLAMConfig, sampling: str, device: torch.device) -> SceneField:
    """The paper's field over room0's bound, same initial planes for either sampling."""
    torch.manual_seed(SEED)
    field_config = dataclasses.replace(config.field, plane_sampling=sampling)
    return SceneField(field_config, torch.tensor(ROOM0_BOUND)).to(device)


def field_query_step(field: SceneField, points: torch.Tensor) -> Callable[[], None]:
    """Query TSDF + colour at ``points`` and backpropagate into the planes and decoders."""

    def step() -> None:
        field.zero_grad(set_to_none=True)
        out = field.query(points)
        (out.sdf.sum() + out.rgb.sum()).backward()

    return step


def tracking_iteration(
    field: SceneField,
    view: View,
    pose: torch.Tensor,
    config: ESLAMConfig,
    generator: torch.Generator,
) -> Callable[[], object]:
    """One iteration of the rendering tracker: :func:`eslam.slam.tracking.tracking_step`
    (call it with the field frozen)."""
    settings = TrackingSettings(config.tracking.render, config.render, config.loss)
    variables = PoseVariables.from_pose(pose)
    optimiser = pose_optimiser(variables, config.tracking.render)

    def step() -> object:
        return tracking_step(field, view, variables, optimiser, settings, generator)

    return step


def mapping_iteration(
    field: SceneField,
    views: list[View],
    poses: torch.Tensor,
    config: ESLAMConfig,
    generator: torch.Generator,
) -> Callable[[], object]:
    """One iteration of :func:`eslam.slam.mapping.mapping_step`: planes, decoders and all
    poses but the oldest."""
    settings = MappingSettings(config.mapping, config.render, config.loss)
    window = WindowPoses.create(poses, [k > 0 for k in range(len(views))])
    optimiser = mapping_optimiser(field, window, config.mapping, lr_factor=1.0)

    def step() -> object:
        return mapping_step(field, views, window, optimiser, settings, generator)

    return step


BENCHMARKS = ("field", "tracking", "mapping")


def run(
    device: torch.device, warmup: int, repeats: int
) -> tuple[dict[tuple[str, str], Stats], dict[str, object]]:
    """Time every benchmark for both plane samplings; also return workload facts."""
    config = ESLAMConfig()
    samples = config.render.samples_stratified + config.render.samples_surface
    data = torch.Generator().manual_seed(SEED)
    views = synthetic_views(WINDOW, config.tracking.border, device, data)
    bound = torch.tensor(ROOM0_BOUND)
    poses = random_poses(WINDOW, bound, data).to(device)
    low, high = bound[:, 0], bound[:, 1]
    points = low + (high - low) * torch.rand(
        config.tracking.render.rays * samples, 3, generator=data
    )
    points = points.to(device)
    results: dict[tuple[str, str], Stats] = {}
    facts: dict[str, object] = {"samples": samples, "points": points.shape[0]}
    for sampling in ("reference", "fast"):
        field = build_field(config, sampling, device)
        facts["parameters"] = field.parameter_count()
        facts["fitted"] = field.bound.cpu().tolist()
        results["field", sampling] = time_iterations(
            field_query_step(field, points), warmup, repeats, device
        )
        generator = torch.Generator(device=device).manual_seed(SEED)
        step = tracking_iteration(field, views[-1], poses[-1], config, generator)
        with frozen(field):
            results["tracking", sampling] = time_iterations(step, warmup, repeats, device)
        generator = torch.Generator(device=device).manual_seed(SEED)
        step = mapping_iteration(field, views, poses, config, generator)
        results["mapping", sampling] = time_iterations(step, warmup, repeats, device)
        del field, step
    return results, facts


def markdown_table(results: dict[tuple[str, str], Stats], config: ESLAMConfig) -> str:
    samples = config.render.samples_stratified + config.render.samples_surface
    labels = {
        "field": f"field query, {config.tracking.render.rays * samples:,} points",
        "tracking": f"tracking iteration, {config.tracking.render.rays} rays",
        "mapping": f"mapping iteration, {config.mapping.rays} rays / {WINDOW} views",
    }
    lines = [
        "| forward + backward (ms) | reference median | reference p90 "
        "| fast median | fast p90 | reference / fast |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name in BENCHMARKS:
        ref, fast = results[name, "reference"], results[name, "fast"]
        lines.append(
            f"| {labels[name]} | {ref.median:.1f} | {ref.p90:.1f} "
            f"| {fast.median:.1f} | {fast.p90:.1f} | {ref.median / fast.median:.2f}x |"
        )
    return "\n".join(lines) + "\n"


def report(
    results: dict[tuple[str, str], Stats],
    facts: dict[str, object],
    device: torch.device,
    args: argparse.Namespace,
    command: str,
    load: tuple[float | None, float | None],
) -> str:
    """The markdown section: heading with date and device, machine, command, table."""
    config = ESLAMConfig()
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    fitted = ", ".join(f"[{lo:g}, {hi:g}]" for lo, hi in facts["fitted"])
    lines = [
        f"## bench_core, {now}, {device.type}",
        "",
        *machine_lines(device, load),
        f"- command: `{command}`",
        f"- workload: Replica room0 bound {ROOM0_BOUND} (fitted [{fitted}]), "
        f"{facts['parameters']:,} learnable field parameters, "
        f"{facts['samples']} samples per ray, synthetic {CAMERA.width}x{CAMERA.height} "
        f"views with random depths in {list(DEPTH_RANGE)} m; "
        f"{args.warmup} warm-up + {args.repeats} timed iterations each",
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    return "\n".join([*lines, "", markdown_table(results, config)])


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="ms per tracking / mapping iteration at the paper's Replica settings, "
        "reference vs fast plane sampling."
    )
    add_device_argument(parser)
    parser.add_argument("--repeats", type=int, default=20, help="timed iterations (default 20)")
    parser.add_argument("--warmup", type=int, default=3, help="untimed iterations (default 3)")
    parser.add_argument(
        "--threads", type=int, default=0, help="torch intra-op threads; 0 = torch's default"
    )
    parser.add_argument("--no-append", action="store_true", help="print only")
    parser.add_argument(
        "--docs", type=Path, default=DEFAULT_DOCS, help="markdown file to append to"
    )
    parser.add_argument("--note", default="", help="a remark printed with the machine")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.warmup < 0 or args.threads < 0:
        parser.error("--repeats must be >= 1, --warmup and --threads >= 0")
    check_device(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    command = command_line("benchmarks/bench_core.py", argv)
    load_start = load_average()
    results, facts = run(device, args.warmup, args.repeats)
    section = report(results, facts, device, args, command, (load_start, load_average()))
    publish(section, args.docs, args.no_append)


if __name__ == "__main__":
    main()
