"""Milliseconds per tracking and mapping iteration at the paper's Replica settings,
where the time goes, and the per-frame work outside the iterations.

1. One tracking iteration (2000 rays) and one mapping iteration (4000 rays over a window
   of 10 keyframes), forward + backward + Adam step, for each plane sampling
   (``FieldConfig.plane_sampling`` reference, fast, fused; triton on CUDA when asked
   for with ``--samplings``), plus the field query alone
   (2000 x 40 points, forward + backward). The samplings are timed interleaved (one
   iteration of each in turn), so their ratios hold on a loaded machine. Every figure
   is the median and the 90th percentile of ``--repeats`` timed iterations after
   ``--warmup`` untimed ones (``time.perf_counter``, with ``torch.cuda.synchronize()``
   around each on CUDA: the steps themselves never sync).
2. Where the time goes: one tracking and one mapping iteration under
   ``torch.profiler``, split into the stages of :data:`eslam.stages.STAGES` (ray
   sampling, plane sampling, decoders, rendering, loss, backward, optimiser step),
   whose regions sit in the real step functions; plus the share of the backward spent
   in plane sampling's autograd nodes. Host time: on a GPU it is launch and Python time.
3. The per-frame work outside the iterations, by the run's own functions: image
   upload, building the frame's View, storing a keyframe, choosing the mapping window
   and building its Views.

The workload needs no dataset: the field spans Replica room0's bound as the authors
publish it (so the planes have the paper's sizes, about 6.6 M learnable parameters)
with the paper's FieldConfig, RenderConfig, LossConfig, TrackingConfig and
MappingConfig defaults; the images are synthetic, Replica-sized (1200 x 680, fx = fy =
600) with seeded random depths in [0.5, 4] m and random colours, seen from seeded random
poses inside the bound. The iterations are the run's own step functions,
:func:`eslam.slam.tracking.render.tracking_step` and :func:`eslam.slam.mapping.mapper.mapping_step`
(no copies), with the optimisers the run builds.

The markdown tables are printed and, unless ``--no-append``, appended to
docs/benchmarks.md (or ``--docs PATH``) with the date, the machine and the command line.

Usage:
    python benchmarks/bench_core.py [--device cpu|cuda] [--repeats N] [--warmup N]
        [--threads N] [--samplings reference fast fused triton] [--breakdown-sampling S]
        [--benchmarks field tracking mapping] [--profile-repeats N] [--no-frame-work]
        [--no-append] [--docs PATH] [--note TEXT]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import time
from collections.abc import Callable

import numpy as np
import torch
from _machine import (
    add_timing_arguments,
    check_timing_arguments,
    command_line,
    load_average,
    machine_lines,
    publish,
)

from eslam.config import ESLAMConfig
from eslam.field.scene_field import SceneField
from eslam.field.triton_sampling import check_device as check_sampling_device
from eslam.geometry.pose import quaternion_to_matrix
from eslam.render.rays import camera_directions
from eslam.slam.mapping.keyframes import KeyframeStore
from eslam.slam.mapping.mapper import MappingSettings, WindowPoses, mapping_optimiser, mapping_step
from eslam.slam.mapping.windows import make_window_strategy
from eslam.slam.tracking.render import (
    PoseVariables,
    TrackingSettings,
    frozen,
    pose_optimiser,
    tracking_step,
)
from eslam.slam.trajectory import Trajectory
from eslam.slam.views import View, make_view, upload_frame
from eslam.stages import STAGES, stage_totals
from eslam.types import Frame, Intrinsics

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
    """The paper's field over room0's bound, same initial planes for either sampling.

    Raises:
        ConfigError: ``triton`` on a device it cannot run on (the message says why).
    """
    check_sampling_device(sampling, device)
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
    """One iteration of the rendering tracker: :func:`eslam.slam.tracking.render.tracking_step`
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
    """One iteration of :func:`eslam.slam.mapping.mapper.mapping_step`: planes, decoders and all
    poses but the oldest."""
    settings = MappingSettings(config.mapping, config.render, config.loss)
    window = WindowPoses.create(poses, [k > 0 for k in range(len(views))])
    optimiser = mapping_optimiser(field, window, config.mapping, lr_factor=1.0)

    def step() -> object:
        return mapping_step(field, views, window, optimiser, settings, generator)

    return step


BENCHMARKS = ("field", "tracking", "mapping")
SAMPLINGS = ("reference", "fast", "fused")
"""The samplings timed by default (they run on any device)."""

SAMPLING_CHOICES = (*SAMPLINGS, "triton")
"""Every sampling ``--samplings`` takes: triton only on CUDA (or in Triton's interpreter)."""


def time_interleaved(
    steps: dict[str, Callable[[], object]], warmup: int, repeats: int, device: torch.device
) -> dict[str, Stats]:
    """Time several steps round-robin (one iteration of each in turn, ``repeats`` rounds
    after ``warmup`` untimed ones), so a change in the machine's load hits all alike."""
    for _ in range(warmup):
        for step in steps.values():
            step()
    times: dict[str, list[float]] = {name: [] for name in steps}
    for _ in range(repeats):
        for name, step in steps.items():
            synchronize(device)
            start = time.perf_counter()
            step()
            synchronize(device)
            times[name].append((time.perf_counter() - start) * 1e3)
    return {name: Stats.of(values) for name, values in times.items()}


@dataclasses.dataclass(frozen=True)
class Workload:
    """The synthetic inputs every benchmark shares."""

    config: ESLAMConfig
    views: list[View]
    poses: torch.Tensor
    points: torch.Tensor


def workload(device: torch.device) -> Workload:
    """Replica-sized views and poses, and field-query points, all seeded."""
    config = ESLAMConfig()
    samples = config.render.samples_stratified + config.render.samples_surface
    data = torch.Generator().manual_seed(SEED)
    views = synthetic_views(WINDOW, config.tracking.border, device, data)
    bound = torch.tensor(ROOM0_BOUND)
    poses = random_poses(WINDOW, bound, data).to(device)
    low, high = bound[:, 0], bound[:, 1]
    count = config.tracking.render.rays * samples
    points = (low + (high - low) * torch.rand(count, 3, generator=data)).to(device)
    return Workload(config, views, poses, points)


def run(
    device: torch.device,
    warmup: int,
    repeats: int,
    samplings: tuple[str, ...],
    benchmarks: tuple[str, ...] = BENCHMARKS,
) -> tuple[dict[tuple[str, str], Stats], dict[str, object]]:
    """Time ``benchmarks`` for each plane sampling, interleaved; also workload facts."""
    work = workload(device)
    config = work.config
    fields = {sampling: build_field(config, sampling, device) for sampling in samplings}
    any_field = next(iter(fields.values()))
    facts: dict[str, object] = {
        "samples": config.render.samples_stratified + config.render.samples_surface,
        "points": work.points.shape[0],
        "parameters": any_field.parameter_count(),
        "fitted": any_field.bound.cpu().tolist(),
    }
    results: dict[tuple[str, str], Stats] = {}
    if "field" in benchmarks:
        steps = {s: field_query_step(f, work.points) for s, f in fields.items()}
        for sampling, stats in time_interleaved(steps, warmup, repeats, device).items():
            results["field", sampling] = stats
        for field in fields.values():
            field.zero_grad(set_to_none=True)
    if "tracking" in benchmarks:
        results |= _tracking_results(fields, work, warmup, repeats, device)
    if "mapping" in benchmarks:
        steps = {
            s: mapping_iteration(
                f, work.views, work.poses, config, torch.Generator(device=device).manual_seed(SEED)
            )
            for s, f in fields.items()
        }
        for sampling, stats in time_interleaved(steps, warmup, repeats, device).items():
            results["mapping", sampling] = stats
    return results, facts


def _tracking_results(
    fields: dict[str, SceneField], work: Workload, warmup: int, repeats: int, device: torch.device
) -> dict[tuple[str, str], Stats]:
    """Tracking iterations of each field, interleaved, with the fields frozen."""
    config = work.config
    steps = {
        s: tracking_iteration(
            f,
            work.views[-1],
            work.poses[-1],
            config,
            torch.Generator(device=device).manual_seed(SEED),
        )
        for s, f in fields.items()
    }
    results = {}
    for field in fields.values():
        field.requires_grad_(False)
    for sampling, stats in time_interleaved(steps, warmup, repeats, device).items():
        results["tracking", sampling] = stats
    for field in fields.values():
        field.requires_grad_(True)
        field.beta.requires_grad_(config.field.learn_beta)
    return results


def profiled_stages(
    step: Callable[[], object], warmup: int, repeats: int, device: torch.device
) -> tuple[dict[str, float], float, float]:
    """Host milliseconds per iteration of each stage (:data:`eslam.stages.STAGES`), of
    the plane-sampling backward nodes, and of the whole iteration, under the profiler.

    The stage regions (``eslam.stages.stage``) sit in the real step functions; the
    plane-sampling backward is the sum of the autograd nodes of ``grid_sample`` or the
    fused op inside the backward stage.
    """
    for _ in range(warmup):
        step()
    synchronize(device)
    activities = [torch.profiler.ProfilerActivity.CPU]
    start = time.perf_counter()
    with torch.profiler.profile(activities=activities) as profile:
        for _ in range(repeats):
            step()
        synchronize(device)
    wall = (time.perf_counter() - start) * 1e3 / repeats
    events = profile.events()
    totals = stage_totals(events)
    plane_backward = sum(
        event.cpu_time_total
        for event in events
        if event.name.startswith("autograd::engine::evaluate_function:")
        and any(key in event.name for key in PLANE_BACKWARD_NODES)
    )
    per_iteration = {name: us / 1e3 / repeats for name, us in totals.items()}
    return per_iteration, plane_backward / 1e3 / repeats, wall


PLANE_BACKWARD_NODES = ("GridSampler2DBackward", "FusedPlaneSamplingBackward")
"""Autograd nodes of plane sampling (reference and fast: grid_sample; fused: the op)."""


def breakdown(
    device: torch.device, sampling: str, warmup: int, repeats: int
) -> dict[str, tuple[dict[str, float], float, float]]:
    """:func:`profiled_stages` of one tracking and one mapping iteration."""
    work = workload(device)
    config = work.config
    field = build_field(config, sampling, device)
    generator = torch.Generator(device=device).manual_seed(SEED)
    step = tracking_iteration(field, work.views[-1], work.poses[-1], config, generator)
    with frozen(field):
        tracking = profiled_stages(step, warmup, repeats, device)
    step = mapping_iteration(field, work.views, work.poses, config, generator)
    mapping = profiled_stages(step, warmup, repeats, device)
    return {"tracking": tracking, "mapping": mapping}


def synthetic_frame(index: int, generator: torch.Generator) -> Frame:
    """A Replica-sized frame with uint8 colour and float32 depths in DEPTH_RANGE."""
    low, high = DEPTH_RANGE
    shape = (CAMERA.height, CAMERA.width)
    depth = (low + (high - low) * torch.rand(shape, generator=generator)).numpy()
    rgb = torch.randint(0, 256, (*shape, 3), generator=generator, dtype=torch.uint8).numpy()
    return Frame(index=index, rgb=rgb, depth=depth, intrinsics=CAMERA)


def per_frame_work(device: torch.device, warmup: int, repeats: int) -> dict[str, Stats]:
    """Milliseconds of the work a frame costs outside the iterations, by the run's own
    functions: upload of its images, its View, and (keyframes) storing it, choosing
    the window and building the window's Views from the store."""
    config = ESLAMConfig()
    data = torch.Generator().manual_seed(SEED)
    frame = synthetic_frame(0, data)
    directions = camera_directions(CAMERA, device=device)
    trajectory = Trajectory(device)
    keyframes = 2 * WINDOW
    poses = random_poses(keyframes, torch.tensor(ROOM0_BOUND), data)
    for k in range(keyframes):
        trajectory.append(poses[k].to(device), float(k), None)
    store = KeyframeStore(CAMERA, trajectory, device, capacity=keyframes + 1)
    for k in range(keyframes):
        store.add(synthetic_frame(k, data), k)
    strategy = make_window_strategy(config.mapping)
    generator = torch.Generator().manual_seed(SEED)
    rgb, depth = upload_frame(frame.rgb, frame.depth, device)
    window = strategy.select(store, keyframes - 1, generator)

    def add_keyframe() -> None:
        store.add(frame, keyframes - 1)
        store.truncate(keyframes)

    steps = {
        "image upload": lambda: upload_frame(frame.rgb, frame.depth, device),
        "view building": lambda: make_view(rgb, depth, directions, config.tracking.border),
        "keyframe storing": add_keyframe,
        "window selection": lambda: strategy.select(store, keyframes - 1, generator),
        f"window views ({len(window)} keyframes)": lambda: [
            make_view(store.rgb(k, device), store.depth(k, device), directions) for k in window
        ],
    }
    return time_interleaved(steps, warmup, repeats, device)


def markdown_table(
    results: dict[tuple[str, str], Stats], config: ESLAMConfig, samplings: tuple[str, ...]
) -> str:
    samples = config.render.samples_stratified + config.render.samples_surface
    labels = {
        "field": f"field query, {config.tracking.render.rays * samples:,} points",
        "tracking": f"tracking iteration, {config.tracking.render.rays} rays",
        "mapping": f"mapping iteration, {config.mapping.rays} rays / {WINDOW} views",
    }
    others = [s for s in samplings if s != "reference"]
    head = "| forward + backward (ms) |"
    rule = "|---|"
    for sampling in samplings:
        head += f" {sampling} median | {sampling} p90 |"
        rule += "---:|---:|"
    if "reference" in samplings:
        for sampling in others:
            head += f" reference / {sampling} |"
            rule += "---:|"
    lines = [head, rule]
    for name in (b for b in BENCHMARKS if (b, samplings[0]) in results):
        row = f"| {labels[name]} |"
        for sampling in samplings:
            stats = results[name, sampling]
            row += f" {stats.median:.1f} | {stats.p90:.1f} |"
        if "reference" in samplings:
            ref = results[name, "reference"].median
            for sampling in others:
                row += f" {ref / results[name, sampling].median:.2f}x |"
        lines.append(row)
    return "\n".join(lines) + "\n"


def breakdown_table(parts: dict[str, tuple[dict[str, float], float, float]]) -> str:
    """Stages as rows, tracking and mapping as columns (host ms per iteration)."""
    lines = [
        "| stage (host ms per iteration) | tracking | mapping |",
        "|---|---:|---:|",
    ]
    for name in STAGES:
        row = f"| {name} | {parts['tracking'][0][name]:.1f} | {parts['mapping'][0][name]:.1f} |"
        lines.append(row)
        if name == "backward":
            lines.append(
                f"| of which plane sampling's backward | {parts['tracking'][1]:.1f} "
                f"| {parts['mapping'][1]:.1f} |"
            )
    rest = {k: v[2] - sum(v[0].values()) for k, v in parts.items()}
    lines.append(
        f"| outside the stages (zero_grad, glue) | {rest['tracking']:.1f} | {rest['mapping']:.1f} |"
    )
    lines.append(
        f"| whole iteration, under the profiler | {parts['tracking'][2]:.1f} "
        f"| {parts['mapping'][2]:.1f} |"
    )
    return "\n".join(lines) + "\n"


def frame_table(work: dict[str, Stats]) -> str:
    lines = ["| per-frame work outside the iterations (ms) | median | p90 |", "|---|---:|---:|"]
    for name, stats in work.items():
        lines.append(f"| {name} | {stats.median:.1f} | {stats.p90:.1f} |")
    return "\n".join(lines) + "\n"


def report(
    results: dict[tuple[str, str], Stats],
    facts: dict[str, object],
    parts: dict[str, tuple[dict[str, float], float, float]] | None,
    frame_work: dict[str, Stats] | None,
    device: torch.device,
    args: argparse.Namespace,
    command: str,
    load: tuple[float | None, float | None],
) -> str:
    """The markdown section: heading with date and device, machine, command, tables."""
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
        f"{args.warmup} warm-up + {args.repeats} timed iterations each, the plane "
        "samplings interleaved (one iteration of each in turn)",
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    sections = [*lines, "", markdown_table(results, config, args.samplings)]
    if parts is not None:
        sections += [
            f"Where the time goes ({args.breakdown_sampling} sampling; host time per stage "
            f"under torch.profiler, mean of {args.profile_repeats} iterations after "
            f"{args.warmup} warm-up; on a GPU this is launch and Python time, not kernel "
            "time):",
            "",
            breakdown_table(parts),
        ]
    if frame_work is not None:
        sections += [frame_table(frame_work)]
    return "\n".join(sections)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="ms per tracking / mapping iteration at the paper's Replica settings "
        "for each plane sampling, where the time goes, and the per-frame work."
    )
    add_timing_arguments(parser, repeats=20, warmup=3)
    parser.add_argument(
        "--samplings",
        nargs="+",
        choices=SAMPLING_CHOICES,
        default=list(SAMPLINGS),
        help="plane samplings to time, interleaved (default: reference fast fused)",
    )
    parser.add_argument(
        "--breakdown-sampling",
        choices=SAMPLING_CHOICES,
        default=ESLAMConfig().field.plane_sampling,
        help="plane sampling of the per-stage breakdown (default: the config default)",
    )
    parser.add_argument(
        "--profile-repeats", type=int, default=5, help="profiled iterations (0: no breakdown)"
    )
    parser.add_argument(
        "--no-frame-work", action="store_true", help="skip the per-frame work outside iterations"
    )
    parser.add_argument(
        "--benchmarks",
        nargs="+",
        choices=BENCHMARKS,
        default=list(BENCHMARKS),
        help="what to time per sampling (default: field, tracking and mapping)",
    )
    args = parser.parse_args(argv)
    args.samplings = tuple(dict.fromkeys(args.samplings))
    args.benchmarks = tuple(dict.fromkeys(args.benchmarks))
    if args.profile_repeats < 0:
        parser.error("--profile-repeats must be >= 0")
    check_timing_arguments(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    device = torch.device(args.device)
    command = command_line("benchmarks/bench_core.py", argv)
    load_start = load_average()
    results, facts = run(device, args.warmup, args.repeats, args.samplings, args.benchmarks)
    parts = None
    if args.profile_repeats > 0:
        parts = breakdown(device, args.breakdown_sampling, args.warmup, args.profile_repeats)
    frame_work = None if args.no_frame_work else per_frame_work(device, args.warmup, args.repeats)
    section = report(
        results, facts, parts, frame_work, device, args, command, (load_start, load_average())
    )
    publish(section, args.docs, args.no_append)


if __name__ == "__main__":
    main()
