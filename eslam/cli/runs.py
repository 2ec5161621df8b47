"""What the commands that run SLAM share (``run``, ``resume``, ``demo``): the process
settings, the metrics lines and the live viewer's options.

Not a command (no ``add``): ``run`` and ``resume`` sit apart in ``eslam --help``
(``configs`` between them), so each has its own module and both import these.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path


def process_settings(config) -> None:
    """What a run asks of the process, set here (the process's owner), never by run_slam:
    torch's CPU threads (``threads=``)."""
    import torch

    if config.threads > 0:
        torch.set_num_threads(config.threads)


def print_metrics(result) -> None:
    """The run folder and one line per metric of a finished run."""
    print(f"run folder: {result.run_dir}")
    for key, value in result.metrics.items():
        shown = f"{value:.4f}" if isinstance(value, float) else str(value)
        print(f"  {key:<20} {shown}")


def viewer(args: argparse.Namespace, config, run_dir: Path):
    """The live viewer's observers (``--viewer``, ``--viewer-save``) as a context; without
    those options none, and nothing of the viewer is imported."""
    if args.viewer is None and args.viewer_save is None:
        return contextlib.nullcontext([])
    from eslam.workflows.live_viewer import viewer_observers

    return viewer_observers(config, run_dir, args.viewer, args.viewer_save)


def add_viewer_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--viewer`` and ``--viewer-save`` to ``parser``."""
    parser.add_argument(
        "--viewer",
        choices=("rerun", "rerun-web"),
        help="show the run live: rerun = a rerun viewer here; rerun-web = served to a "
        "browser (ports 9090 and 9876); needs the [viewer] extra (docs/live.md)",
    )
    parser.add_argument(
        "--viewer-save", type=Path, metavar="FILE.rrd", help="record the viewer's stream to a file"
    )
