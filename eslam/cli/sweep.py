"""``eslam sweep`` and ``eslam table``: a grid of runs from a sweep file, and the table
of its finished cells (docs/sweeps.md)."""

from __future__ import annotations

import argparse

from eslam.cli.args import positive_int

BACKENDS = ("local", "ray")
"""``--backend``'s choices: the names of
:data:`eslam.workflows.sweep.SWEEP_BACKENDS` (a test holds them equal; that module
imports torch, so building the parser does not import it)."""


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``sweep`` and ``table`` to ``commands``."""
    sweep = commands.add_parser(
        "sweep",
        help="run a grid of runs (datasets x variants x seeds) from a sweep file, resumable",
        description=(
            "Run and evaluate every cell of SWEEP (a YAML sweep file, docs/sweeps.md) into "
            "OUT/<dataset>/<variant>/seed<k>/; finished cells of the same config are "
            "skipped, failed ones recorded in their cell.json. Exit status 1 when a cell "
            "failed. Then `eslam table OUT`."
        ),
    )
    sweep.add_argument("sweep", metavar="SWEEP", help="sweep file (YAML)")
    sweep.add_argument("overrides", nargs="*", metavar="key=value", help="every cell, last")
    sweep.add_argument("--out", required=True, help="output folder (shared by all Ray nodes)")
    sweep.add_argument("--backend", choices=BACKENDS, default="local", help="(local)")
    sweep.add_argument(
        "--jobs", type=positive_int, default=1, help="local: cells at a time, in processes (1)"
    )
    sweep.add_argument(
        "--address", help="ray: cluster to join (auto, HOST:6379); default a new one"
    )
    sweep.add_argument("--datasets", metavar="A,B", help="run only these datasets of SWEEP")
    sweep.add_argument("--variants", metavar="A,B", help="run only these variants of SWEEP")
    sweep.add_argument(
        "--dry-run", action="store_true", help="check the input, print the cells, run nothing"
    )
    sweep.set_defaults(handler=handle_sweep)

    table = commands.add_parser(
        "table",
        help="mean +- std over seeds of a sweep's cells, beside the paper's numbers",
        description=(
            "Aggregate the finished cells under DIR (eslam sweep --out DIR) into "
            "DIR/table.md, table.csv, table.json and DIR/plots/<metric>.png."
        ),
    )
    table.add_argument("dir", metavar="DIR", help="the output folder of eslam sweep")
    table.add_argument("--no-plots", action="store_true", help="tables only (no matplotlib)")
    table.set_defaults(handler=handle_table)


def handle_sweep(args: argparse.Namespace) -> int:
    """Run the sweep (or, with --dry-run, print its cells); exit status 1 when a cell
    failed."""
    from eslam.workflows.sweep import run_sweep
    from eslam.workflows.sweep_cells import check_inputs, describe_cells, plan_cells
    from eslam.workflows.sweep_file import load_sweep

    names = [[n for n in (text or "").split(",") if n] for text in (args.datasets, args.variants)]
    sweep = load_sweep(args.sweep).select(*names)
    if args.dry_run:
        cells = plan_cells(sweep, args.out, args.overrides)
        check_inputs(cells)
        print(describe_cells(cells))
        return 0
    summary = run_sweep(
        sweep, args.out, args.backend, args.jobs, args.address, extra=args.overrides
    )
    print(summary.text())
    if summary.count("done") + summary.count("skipped"):
        print(f"tables: eslam table {args.out}")
    return 1 if summary.failed else 0


def handle_table(args: argparse.Namespace) -> int:
    """Write the sweep's tables (and plots); print what was written."""
    from eslam.workflows.table import write_table

    result = write_table(args.dir, plots=not args.no_plots)
    print(f"wrote {', '.join(str(path) for path in result.files[:3])} ({len(result.rows)} rows)")
    if result.unfinished:
        print(f"left out {len(result.unfinished)} unfinished cells (listed in table.md)")
    return 0
