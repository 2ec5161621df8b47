"""``eslam inspect``: read and check every frame of a sequence, print a summary."""

from __future__ import annotations

import argparse

from eslam.cli.args import positive_float


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``inspect`` to ``commands``."""
    from eslam.data import DATASETS

    inspect = commands.add_parser(
        "inspect",
        help="read and check every frame of a sequence, print a summary",
        description=(
            "Read every frame of a sequence with its reader, check it (images, depth, "
            "poses) and print frame count, camera, depth range and trajectory length."
        ),
    )
    inspect.add_argument("path", metavar="PATH", help="sequence folder")
    inspect.add_argument(
        "--format", choices=sorted(DATASETS), default="replica", help="dataset layout"
    )
    inspect.add_argument(
        "--depth-scale",
        type=positive_float,
        metavar="UNITS",
        help="depth units per metre (sets data.depth_scale; default: the layout's own)",
    )
    inspect.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Print the sequence's summary; a depth problem is the one-line error after it."""
    from eslam.config import DataConfig
    from eslam.data import open_sequence
    from eslam.data.inspect import inspect_sequence

    sequence = open_sequence(
        DataConfig(format=args.format, path=args.path, depth_scale=args.depth_scale)
    )
    summary = inspect_sequence(sequence)
    print(summary.to_text())
    if summary.depth_problem is not None:
        raise summary.depth_problem  # the one line a run would stop with, exit status 2
    return 0
