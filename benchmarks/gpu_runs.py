"""The whole runs of benchmarks/gpu_check.py: what runs, one run in this process, its row.

Each run reads a sequence under the check's data root (as ``benchmarks/gpu_pack.py``
lays it out) with a shipped config, meshing off, and reports the figures the GPU issue
asks for: frames per second over the whole run, tracking and mapping milliseconds per
iteration, the first tracked pose from the process's start (cold) and, for the first
case, from a second run in the same process (warm), peak memory, ATE, and whether the
iterations ran as CUDA-graph replays (from the run's log.txt).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

from _machine import REPO

from eslam.config import load_config
from eslam.slam.run.observers import FrameDone, MappingDone, RunObserverBase
from eslam.slam.session import run_slam

CONFIGS = REPO / "eslam" / "configs"
FAST_FIRST_FRAME = (
    "tracking.method=hybrid",
    "mapping.first_warm_start=tsdf",
    "mapping.first_iterations=30",
    "mapping.first_lr_factor=2.0",
)
"""room0's fast preset on a GPU: the paper's settings with the hybrid tracker and the
fast first frame (TSDF warm start + 30 steps at twice the rates), as docs/results.md."""

SMOKE = (
    "mapping.first_iterations=5",
    "mapping.iterations=2",
    "mapping.first_warm_start=none",
    "tracking.render.iterations=3",
)
"""--smoke on the CPU: a few iterations, only to show every part runs."""


@dataclass(frozen=True)
class RunSpec:
    """One whole run of the check.

    Attributes:
        name: the row's label (and the run folder's name).
        config: config file, relative to eslam/configs.
        data: sequence folder under the data root.
        frames: frames from frame 0 (fewer when the packed sequence has fewer).
        overrides: config overrides on top of the config.
        first_s / frame_s: a guess of the first frame's and each later frame's seconds
            on an H100 at these settings, so that steps that would not fit are skipped.
        warm: run a second time in the same process (the warm first pose).
    """

    name: str
    config: str
    data: str
    frames: int
    overrides: tuple[str, ...] = ()
    first_s: float = 10.0
    frame_s: float = 0.3
    warm: bool = False

    def estimate_s(self, frames: int, cuda: bool) -> float:
        """Seconds the run should take in a fresh process (start-up included)."""
        start = 15.0 if cuda else 30.0
        runs = 2 if self.warm else 1
        if not cuda:  # --smoke: a few iterations per frame on the CPU
            return start + runs * frames * 20.0
        return start + runs * (self.first_s + frames * self.frame_s)


RUNS = (
    RunSpec("room0-paper", "replica/room0.yaml", "replica-room0", 20, (), 25.0, 0.2, True),
    RunSpec("room0-fast", "replica/room0.yaml", "replica-room0", 20, FAST_FIRST_FRAME, 5.0),
    RunSpec("redkitchen", "sevenscenes/redkitchen.yaml", "7scenes-redkitchen", 200),
    RunSpec("tum-fr1-xyz", "tum/fr1_xyz.yaml", "tum-fr1-xyz", 200, (), 20.0, 1.0),
    RunSpec("tum-fr1-xyz-cpu-preset", "tum/tum_cpu.yaml", "tum-fr1-xyz", 200),
)


@dataclass(frozen=True)
class Variant:
    """Settings of the compute path compared in each run."""

    overrides: tuple[str, ...]
    needs_cuda: bool


VARIANTS = {
    "eager": Variant(("compute.cuda_graphs=off", "field.plane_sampling=fused"), False),
    "graphs+triton": Variant(("compute.cuda_graphs=auto", "field.plane_sampling=triton"), True),
}


@dataclass(frozen=True)
class RunFigures:
    """One whole run's figures (saved as JSON by the child process)."""

    name: str
    config: str
    variant: str
    frames: int
    fps: float
    tracking_ms: float
    mapping_ms: float
    first_cold_s: float
    first_warm_s: float
    peak_mb: float
    ate_cm: float
    failed: int
    graphs: str


class RunClock(RunObserverBase):
    """When frame 0 was done (tracked, mapped, written), by time.perf_counter(), and
    the iterations of each mapping call by frame."""

    def __init__(self) -> None:
        self.frame0_done: float | None = None
        self.mapping_iterations: dict[int, int] = {}

    def on_frame(self, frame: FrameDone) -> None:
        if frame.index == 0:
            self.frame0_done = time.perf_counter()

    def on_mapping(self, mapping: MappingDone) -> None:
        self.mapping_iterations[mapping.index] = mapping.iterations


def run_one(
    spec: RunSpec, variant: str, frames: int, args: argparse.Namespace, process_start: float
) -> RunFigures:
    """Run ``spec`` with ``variant`` in this process (twice when ``spec.warm``)."""
    overrides = [
        f"data.path={args.data_root / spec.data}",
        f"data.max_frames={frames}",
        f"device={args.device}",
        f"threads={args.threads}",
        "output.progress=false",
        "output.mesh=false",
        *spec.overrides,
        *VARIANTS[variant].overrides,
        *(SMOKE if args.smoke else ()),
    ]
    config = load_config(CONFIGS / spec.config, overrides)
    out = args.out / "runs" / f"{spec.name}-{variant}"
    result, wall, first, clock = _timed_run(config, out, process_start)
    warm = _timed_run(config, out.with_name(out.name + "-warm"), None) if spec.warm else None
    metrics = result.metrics
    timings = _timings(result.run_dir)
    for run in (out, out.with_name(out.name + "-warm")):  # maps stay: only figures go back
        (run / "map.pt").unlink(missing_ok=True)
    render_iterations = config.tracking.render.iterations  # the render tracker logs none
    tracking_iterations = [
        render_iterations if n is None else n
        for n in timings.get("tracking_iterations", [None] * len(timings["tracking_s"]))
    ]
    mapping_iterations = [
        clock.mapping_iterations.get(index, 0) for index in range(len(timings["mapping_s"]))
    ]
    return RunFigures(
        name=spec.name,
        config=spec.config + "".join(f" {o}" for o in spec.overrides),
        variant=variant,
        frames=metrics["frames"],
        fps=metrics["frames"] / wall,
        tracking_ms=_per_iteration(timings["tracking_s"], tracking_iterations),
        mapping_ms=_per_iteration(timings["mapping_s"], mapping_iterations),
        first_cold_s=first,
        first_warm_s=warm[2] if warm else math.nan,
        peak_mb=metrics["peak_memory_mb"],
        ate_cm=metrics.get("ate_rmse_cm", math.nan),
        failed=int(metrics.get("tracking_failures", 0)),
        graphs=graphs_note(result.run_dir / "log.txt", variant),
    )


def _timed_run(config, out: Path, start: float | None):
    """run_slam: (result, wall seconds, the first pose's time from ``start`` (the run's
    own start if None): frame 0 done, plus frame 1's tracking, the run's clock)."""
    clock = RunClock()
    begin = time.perf_counter()
    result = run_slam(config, out, overwrite=True, observers=[clock])
    wall = time.perf_counter() - begin
    tracking = _timings(result.run_dir)["tracking_s"]
    first = math.nan
    if clock.frame0_done is not None and len(tracking) > 1:
        first = clock.frame0_done - (begin if start is None else start) + tracking[1]
    return result, wall, first, clock


def _timings(run_dir: Path) -> dict:
    import json

    return json.loads((run_dir / "timings.json").read_text())


def _per_iteration(seconds: list[float], iterations: list[float]) -> float:
    """Median milliseconds per iteration over frames 1.. that ran any (frame 0's
    first mapping call is the first pose's figure)."""
    ratios = [
        1000.0 * s / n for s, n in list(zip(seconds, iterations, strict=True))[1:] if s > 0 and n
    ]
    return statistics.median(ratios) if ratios else math.nan


def graphs_note(log: Path, variant: str) -> str:
    """How the iterations ran, from the run's log: graph replays, eager (and why), or a
    capture that failed (the iterations then ran eagerly)."""
    if not VARIANTS[variant].overrides[0].endswith("auto"):
        return "off"
    text = log.read_text() if log.is_file() else ""
    if "capturing an iteration failed" in text:
        return "capture failed, eager"
    if "each iteration is a CUDA-graph replay" in text:
        return "replayed"
    if "run eagerly" in text:
        return "eager: " + text.split("run eagerly (", 1)[1].split(")", 1)[0]
    return "not logged"


def table_head() -> list[str]:
    return [
        "| run | config | compute | frames | FPS (whole run) | tracking (ms/iter) "
        "| mapping (ms/iter) | first pose cold (s) | first pose warm (s) | peak memory (MB) "
        "| ATE (cm) | failed frames | graphs |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]


def row_cells(figures: dict) -> str:
    f = RunFigures(**figures)
    return (
        f"| {f.name} | `{f.config}` | {f.variant} | {f.frames} | {f.fps:.2f} "
        f"| {f.tracking_ms:.2f} | {f.mapping_ms:.2f} | {f.first_cold_s:.2f} "
        f"| {f.first_warm_s:.2f} | {f.peak_mb:.0f} | {f.ate_cm:.3f} | {f.failed} | {f.graphs} |"
    )
