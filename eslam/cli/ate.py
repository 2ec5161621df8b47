"""``eslam ate``: absolute trajectory error (and relative pose error) of two trajectories.

The errors come from :func:`eslam.workflows.trajectory_metrics.trajectory_errors`; this
module parses the arguments and prints the table or JSON.
"""

from __future__ import annotations

import argparse

from eslam.cli.args import non_negative_float

ALIGNMENTS = ("se3", "sim3")
"""``--align``'s choices: :data:`eslam.workflows.trajectory_metrics.ALIGNMENTS` (a test
holds them equal; the workflow is not imported to build the parser)."""


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``ate`` to ``commands``."""
    ate = commands.add_parser(
        "ate",
        help="absolute trajectory error (and relative pose error) between two trajectories",
        description=(
            "ATE after Umeyama alignment of the estimate onto the ground truth: RMSE, mean, "
            "median, max (cm). GT and EST are TUM files (timestamp tx ty tz qx qy qz qw), "
            "Replica traj.txt files (16 numbers per line; timestamps = line numbers) or run "
            "folders (GT reads trajectory_gt.txt, EST trajectory.txt). Poses are matched by "
            "timestamp; pairs with a missing (nan/inf) pose are left out and counted."
        ),
    )
    ate.add_argument("gt", metavar="GT", help="ground-truth trajectory file or run folder")
    ate.add_argument("est", metavar="EST", help="estimated trajectory file or run folder")
    ate.add_argument(
        "--align",
        choices=ALIGNMENTS,
        default="se3",
        help="rigid (se3, the paper's) or similarity (sim3) alignment",
    )
    ate.add_argument(
        "--max-diff",
        type=non_negative_float,
        default=0.01,
        metavar="S",
        help="largest timestamp difference of a matched pair, seconds (default 0.01)",
    )
    ate.add_argument("--json", action="store_true", help="print JSON instead of a table")
    ate.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Print the trajectory errors as a table, or as JSON with both paths."""
    from eslam.evaluate.report import titled_table
    from eslam.io.run_dir import json_text
    from eslam.workflows.trajectory_metrics import trajectory_errors

    metrics = trajectory_errors(args.gt, args.est, args.align, args.max_diff).as_dict()
    if args.json:
        print(json_text({**metrics, "gt": args.gt, "est": args.est}))
    else:
        print(titled_table(f"ATE of {args.est} against {args.gt}", metrics))
    return 0
