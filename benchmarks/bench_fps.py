"""Frames per second of whole runs at the paper's Replica settings, on a synthetic sequence.

A Replica-size (1200x680, 90 degree field of view as Replica's fx = 600) synthetic room
of ``--frames`` frames (default 300) is written under ``--out`` once and reused; the
run uses configs/replica/room0.yaml (the paper's Replica settings) with the synthetic
scene's bound, no mesh. Printed (and, with ``--docs``, appended to docs/benchmarks.md):

- FPS (wall) = frames / wall time of the run, everything included (metrics.json
  ``fps_wall``), and the same after the first frame (``fps_wall_after_first``: without
  the map's first mapping call and warm-up);
- tracking-only FPS = frames / total tracking time (``fps_tracking``, Co-SLAM's
  definition, for comparison with papers that report it);
- the time to the first tracked pose (from the run's start to the end of frame 1's
  tracking: frame 0's pose is given, its mapping call is the long one);
- peak memory (the CUDA allocator's peak on a GPU, else the resident set) and ATE RMSE.

Full size takes hours on a 2-core CPU; ``--frames`` and ``--size`` make smoke runs:

    python benchmarks/bench_fps.py --device cuda --docs          # 300 frames, 1200x680
    python benchmarks/bench_fps.py --device cpu --frames 5 --size 120x68   # smoke

``--docs`` appends the section to docs/benchmarks.md (``--docs-file`` for another file).
Trailing ``key=value`` overrides apply after the Replica settings (e.g.
``tracking.method=render``). At a smaller ``--size`` the tracking border (75 pixels at
1200x680) is scaled with the width.
"""

from __future__ import annotations

import argparse
import sys
import time
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
from eslam.slam.run.observers import FrameDone, RunObserverBase, RunStart
from eslam.slam.session import RunResult, run_slam

CONFIG = REPO / "eslam" / "configs" / "replica" / "room0.yaml"
REPLICA_SIZE = (1200, 680)
REPLICA_HFOV_DEG = 90.0
"""Replica's renderings: fx = 600 at 1200 pixels wide, 2 atan(600 / 600) = 90 degrees."""
REPLICA_BORDER = 75
"""configs/replica/replica.yaml's tracking.border at 1200 pixels wide."""


class FirstTrackedPose(RunObserverBase):
    """Seconds from the run's start to the end of the first tracked frame's tracking."""

    def __init__(self) -> None:
        self.began = 0.0
        self.seconds: float | None = None

    def on_start(self, start: RunStart) -> None:
        self.began = time.perf_counter()

    def on_frame(self, frame: FrameDone) -> None:
        if self.seconds is None and frame.tracked:
            # on_frame follows the frame's mapping call: the pose was ready before it
            self.seconds = time.perf_counter() - frame.mapping_s - self.began


def parse_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got '{text}'") from None
    if width < 8 or height < 8:
        raise argparse.ArgumentTypeError(f"the image must be at least 8x8, got {text}")
    return width, height


def synthetic_sequence(out: Path, frames: int, size: tuple[int, int]) -> Path:
    """The benchmark's sequence under ``out`` (written once per frame count and size)."""
    from eslam.synthetic import SynthConfig, write_synthetic_sequence

    width, height = size
    data = out / f"data-{width}x{height}-{frames}"
    if not (data / "synth.json").is_file():
        config = SynthConfig(
            frames=frames, width=width, height=height, seed=0, hfov_deg=REPLICA_HFOV_DEG
        )
        write_synthetic_sequence(data, config, overwrite=True)
    return data


def run(args: argparse.Namespace, data: Path) -> tuple[RunResult, float | None]:
    """The run at the Replica settings; its result and the time to the first tracked pose."""
    from eslam.synthetic import read_synthetic_bound

    border = round(REPLICA_BORDER * args.size[0] / REPLICA_SIZE[0])
    overrides = [
        f"data.path={data}",
        f"scene.bound={read_synthetic_bound(data)}",
        f"tracking.border={border}",
        f"device={args.device}",
        f"threads={args.threads}",
        "output.progress=false",
        "output.mesh=false",
        *args.overrides,
    ]
    config = load_config(CONFIG, overrides)
    if config.threads > 0:
        torch.set_num_threads(config.threads)
    first = FirstTrackedPose()
    result = run_slam(config, args.out / "run", overwrite=True, observers=[first])
    return result, first.seconds


def table(result: RunResult, first_pose_s: float | None, size: tuple[int, int]) -> str:
    m = result.metrics
    nan = float("nan")
    first = nan if first_pose_s is None else first_pose_s
    lines = [
        "| frames | size | FPS (wall) | FPS after frame 0 (wall) | tracking-only FPS "
        "| first tracked pose (s) | peak memory (MB) | ATE RMSE (cm) |",
        "|---:|---|---:|---:|---:|---:|---:|---:|",
        f"| {m['frames']} | {size[0]}x{size[1]} | {m.get('fps_wall', nan):.3f} "
        f"| {m.get('fps_wall_after_first', nan):.3f} | {m.get('fps_tracking', nan):.3f} "
        f"| {first:.1f} | {m['peak_memory_mb']:.0f} | {m.get('ate_rmse_cm', nan):.2f} |",
    ]
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_device_argument(parser)
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    parser.add_argument("--frames", type=int, default=300, help="frames of the sequence")
    parser.add_argument(
        "--size", type=parse_size, default=REPLICA_SIZE, help="WIDTHxHEIGHT (1200x680)"
    )
    parser.add_argument("--out", type=Path, default=Path("runs/bench_fps"))
    parser.add_argument(
        "--docs", action="store_true", help="append the section to --docs-file as well"
    )
    parser.add_argument("--docs-file", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--note", default="")
    parser.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    args = parser.parse_intermixed_args(argv)  # overrides may come before options
    if args.frames < 2:
        parser.error("--frames must be >= 2 (the first tracked pose is frame 1's)")
    check_device(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    device = torch.device(args.device)
    command = command_line("benchmarks/bench_fps.py", argv)
    data = synthetic_sequence(args.out, args.frames, args.size)
    load_start = load_average()
    result, first_pose_s = run(args, data)
    lines = section_head(
        "bench_fps",
        device,
        (load_start, load_average()),
        command,
        "synthetic room (seed 0, 90 degree field of view), written by eslam.synthetic; "
        "settings: `configs/replica/room0.yaml` with the scene's bound, no mesh; FPS "
        "definitions in docs/evaluation.md (metrics.json)",
        ("overrides", args.overrides),
        args.note,
    )
    section = "\n".join([*lines, "", table(result, first_pose_s, args.size)])
    publish(section, args.docs_file, print_only=not args.docs)


if __name__ == "__main__":
    main()
