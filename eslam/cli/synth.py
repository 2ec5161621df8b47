"""``eslam synth``: write a synthetic RGB-D sequence with exact ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from eslam.cli.args import image_size, positive_int


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``synth`` to ``commands``."""
    from eslam.synthetic import SCENES, SynthConfig
    from eslam.synthetic.config import TRAJECTORIES

    defaults = SynthConfig()
    synth = commands.add_parser(
        "synth",
        help="write a synthetic RGB-D sequence with exact ground truth (Replica layout)",
        description=(
            "Render a procedural room by exact ray casting and write it in the Replica "
            "layout: results/frame*.jpg, results/depth*.png, traj.txt, cam_params.json, "
            "plus the ground-truth mesh.ply and synth.json."
        ),
    )
    synth.add_argument("out_dir", metavar="OUT_DIR", help="folder to create")
    synth.add_argument(
        "--frames", type=positive_int, default=defaults.frames, help="frames to render"
    )
    synth.add_argument(
        "--size",
        type=image_size,
        default=(defaults.width, defaults.height),
        metavar="WxH",
        help=f"image size (default {defaults.width}x{defaults.height})",
    )
    synth.add_argument("--seed", type=int, default=defaults.seed, help="scene and trajectory seed")
    synth.add_argument(
        "--scene", choices=sorted(SCENES), default=defaults.scene, help="scene builder"
    )
    synth.add_argument(
        "--trajectory",
        choices=TRAJECTORIES,
        default=defaults.trajectory,
        help="camera path: sway (hand-held-like) or loop (laps around the room: a "
        "sequence longer than a lap returns to where it began)",
    )
    synth.add_argument(
        "--focal-error",
        type=focal_error,
        default=defaults.focal_error,
        metavar="E",
        help="the frames report a focal length x (1 + E) (e.g. 0.01): odometry drifts, "
        "the ground truth stays exact",
    )
    synth.add_argument("--depth-noise", action="store_true", help="add sensor-like depth noise")
    synth.add_argument(
        "--missing-depth", action="store_true", help="drop depth like a sensor does (0 = invalid)"
    )
    synth.add_argument("--overwrite", action="store_true", help="replace OUT_DIR if it exists")
    synth.set_defaults(handler=handle)


def focal_error(text: str) -> float:
    """``--focal-error``: a float in (-0.5, 0.5)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: '{text}'") from None
    if not -0.5 < value < 0.5:
        raise argparse.ArgumentTypeError(f"must be in (-0.5, 0.5), got {value}")
    return value


def handle(args: argparse.Namespace) -> int:
    """Write the sequence; print what was written."""
    from eslam.synthetic import SynthConfig, write_synthetic_sequence

    width, height = args.size
    config = SynthConfig(
        frames=args.frames,
        width=width,
        height=height,
        seed=args.seed,
        scene=args.scene,
        trajectory=args.trajectory,
        focal_error=args.focal_error,
        depth_noise=args.depth_noise,
        missing_depth=args.missing_depth,
    )
    out_dir = write_synthetic_sequence(Path(args.out_dir), config, overwrite=args.overwrite)
    print(f"wrote {config.frames} frames ({width}x{height}, scene '{config.scene}') to {out_dir}")
    return 0
