"""``eslam resume``: continue an interrupted run from its last checkpoint."""

from __future__ import annotations

import argparse
from pathlib import Path

from eslam.cli.runs import add_viewer_options, print_metrics, process_settings, viewer


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``resume`` to ``commands``."""
    resume = commands.add_parser(
        "resume",
        help="continue an interrupted run from its last checkpoint",
        description=(
            "Continue the run in RUN_DIR from its last checkpoint (map.pt), or from frame 0 "
            "when it stopped before saving one. The sequence must be the one the run "
            "started on (frame count, first and last files, camera: input.json); "
            "--data points to it where it moved. See docs/reliability.md."
        ),
    )
    resume.add_argument("run_dir", metavar="RUN_DIR", help="folder of the interrupted run")
    resume.add_argument(
        "--data", metavar="PATH", help="the run's sequence, where it moved (sets data.path)"
    )
    add_viewer_options(resume)
    resume.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Resume the run in ``args.run_dir`` with its own config; print the metrics."""
    import dataclasses
    import os

    from eslam.config import load_config
    from eslam.errors import InputError
    from eslam.io.run_dir import RunDirectory
    from eslam.slam.session import run_slam

    run = RunDirectory(Path(args.run_dir))
    if not run.config.is_file():
        problem = "not found: not a run folder" if run.root.is_dir() else "run folder not found"
        raise InputError(
            run.config if run.root.is_dir() else run.root,
            problem,
            "pass the folder of a run started with `eslam run CONFIG --out RUN_DIR`",
        )
    config = load_config(run.config)
    if args.data is not None:  # the data moved: its fingerprint must still match
        data = dataclasses.replace(config.data, path=os.path.abspath(args.data))
        config = dataclasses.replace(config, data=data)
    process_settings(config)
    with viewer(args, config, run.root) as observers:
        print_metrics(run_slam(config, run.root, resume=True, observers=observers))
    return 0
