"""``eslam render``: colour and depth views of a run's saved map (docs/render.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from eslam.cli.args import image_size, positive_float, positive_int


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``render`` to ``commands``."""
    from eslam.workflows.render_views import DEFAULT_ORBIT_VIEWS

    render = commands.add_parser(
        "render",
        help="render colour and depth views from a run's map.pt (no input depth)",
        description=(
            "Render views of the saved map along the run's estimated trajectory (default), "
            "a trajectory file or an orbit, with the run's camera: OUT/colour/NNNNNN.png "
            "(8-bit RGB), OUT/depth/NNNNNN.png (16-bit millimetres, 0 = nothing hit) and "
            "OUT/video.mp4 (needs imageio-ffmpeg, the [viewer] extra). See docs/render.md."
        ),
    )
    render.add_argument("run_dir", metavar="RUN_DIR", help="folder of a run (config.yaml, map.pt)")
    path = render.add_mutually_exclusive_group()
    path.add_argument(
        "--trajectory",
        metavar="FILE",
        help="poses to render: TUM file, Replica traj.txt or run folder (default: the run's)",
    )
    path.add_argument(
        "--orbit",
        nargs="?",
        const=DEFAULT_ORBIT_VIEWS,
        type=positive_int,
        metavar="N",
        help=f"N views on a circle around the scene's centre (default {DEFAULT_ORBIT_VIEWS})",
    )
    render.add_argument(
        "--size", type=image_size, metavar="WxH", help="image size (default: the run's)"
    )
    render.add_argument("--out", metavar="DIR", help="output folder (default RUN_DIR/render)")
    render.add_argument(
        "--device", default="cpu", help="auto, cpu, cuda, cuda:N or mps (default cpu)"
    )
    render.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    render.add_argument(
        "--fps", type=positive_float, default=30.0, help="video frame rate (default 30)"
    )
    render.add_argument("--no-video", action="store_true", help="images only, no video.mp4")
    render.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Render the views; print how many, where, and the video (or why there is none)."""
    from eslam.workflows.render_views import RenderOptions, render_run

    options = RenderOptions(
        trajectory=Path(args.trajectory) if args.trajectory else None,
        orbit=args.orbit,
        size=args.size,
        out=Path(args.out) if args.out else None,
        device=args.device,
        overwrite=args.overwrite,
        video=not args.no_video,
        fps=args.fps,
    )
    result = render_run(args.run_dir, options)
    width, height = result.size
    skipped = f", {result.skipped} missing poses skipped" if result.skipped else ""
    print(f"wrote {result.views} views ({width}x{height}{skipped}) to {result.out}")
    print(f"video: {result.video}" if result.video is not None else result.video_note)
    return 0
