"""``eslam run``: run ESLAM on a sequence (or a live camera) and write a run folder."""

from __future__ import annotations

import argparse
import textwrap
from pathlib import Path

from eslam.cli.args import SETTINGS_WIDTH, image_size, positive_int, settings_epilog
from eslam.cli.runs import add_viewer_options, print_metrics, process_settings, viewer


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``run`` to ``commands`` (its help lists every setting)."""
    run = commands.add_parser(
        "run",
        help="run ESLAM on a sequence and write a run folder",
        description=textwrap.fill(
            "Track every frame and map every k-th; write config.yaml, trajectory.txt "
            "(TUM), trajectory_gt.txt, map.pt, mesh.ply, metrics.json and timings.json. "
            "Settings are `key.sub=value` overrides of CONFIG (listed below).",
            SETTINGS_WIDTH,
        ),
        epilog=settings_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument(
        "config",
        metavar="CONFIG",
        help="YAML config file, or a packaged config's name from any directory "
        "(e.g. replica/room0; `eslam configs` lists them)",
    )
    run.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    run.add_argument("--data", help="sequence folder (sets data.path)")
    run.add_argument("--out", help="run folder (default runs/NAME-TIME)")
    run.add_argument("--device", help="auto, cpu, cuda, cuda:N or mps (sets device)")
    run.add_argument("--start", type=int, help="first frame to use (sets data.start)")
    run.add_argument("--stride", type=int, help="use every N-th frame (sets data.stride)")
    run.add_argument("--max-frames", type=int, help="use at most N frames (sets data.max_frames)")
    run.add_argument("--overwrite", action="store_true", help="reuse an existing run folder")
    run.add_argument(
        "--realtime",
        action="store_true",
        help="drop frames that arrive while busy, keep the newest; replay a recording at its "
        "recorded rate (sets data.realtime; always on for a live camera; docs/live.md)",
    )
    run.add_argument(
        "--source",
        metavar="realsense[:SERIAL]",
        help="a live RealSense camera instead of --data (docs/live.md; the realsense extra)",
    )
    run.add_argument(
        "--camera-size", type=image_size, default=(640, 480), metavar="WxH",
        help="live camera: depth and colour size (default 640x480)",
    )  # fmt: skip
    run.add_argument(
        "--camera-fps", type=positive_int, default=30, help="live camera: frame rate (30)"
    )
    add_viewer_options(run)
    run.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Load the config with the options as overrides, run, print the metrics."""
    from eslam.config import load_config
    from eslam.io.run_dir import default_run_name
    from eslam.slam.session import run_slam

    overrides = list(args.overrides)
    if args.data is not None:
        overrides.append(f"data.path={args.data}")
    if args.device is not None:
        overrides.append(f"device={args.device}")
    for option in ("start", "stride", "max_frames"):
        if getattr(args, option) is not None:
            overrides.append(f"data.{option}={getattr(args, option)}")
    if args.realtime:
        overrides.append("data.realtime=true")
    config = load_config(args.config, overrides)
    out = Path(args.out) if args.out else Path(default_run_name(args.config))
    process_settings(config)
    source = None
    if args.source is not None:
        from eslam.data.realsense import open_camera

        source = open_camera(args.source, args.camera_size, args.camera_fps, config.data)
    try:
        with viewer(args, config, out) as observers:
            result = run_slam(
                config, out, overwrite=args.overwrite, source=source, observers=observers
            )
        print_metrics(result)
    finally:
        if source is not None:
            source.close()
    return 0
