"""``eslam demo``: a synthetic scene end to end (generate, run, evaluate)."""

from __future__ import annotations

import argparse
from pathlib import Path

from eslam.cli.runs import process_settings


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``demo`` to ``commands``."""
    demo = commands.add_parser(
        "demo",
        help="synthetic scene, end to end: generate, run, evaluate (a few minutes on CPU)",
        description=(
            "Write a 60-frame synthetic room to OUT/data, run ESLAM with the CPU preset "
            "(configs/demo.yaml) to OUT/run and print the metrics."
        ),
    )
    demo.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    demo.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    demo.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Run the demo; print the run folder and its metrics."""
    from eslam.evaluate.report import metrics_text
    from eslam.workflows.demo import demo_config, run_demo

    config = demo_config(Path(args.out), tuple(args.overrides))
    process_settings(config)
    result = run_demo(Path(args.out), config)
    print(f"run folder: {result.run_dir} (report.md holds the table and plots)")
    print(metrics_text(result.metrics))
    return 0
