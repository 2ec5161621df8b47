"""``eslam eval``: score a finished run (ATE, mesh metrics against a GT mesh, report.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from eslam.cli.args import non_negative_int, positive_int


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``eval`` to ``commands``."""
    evaluation = commands.add_parser(
        "eval",
        help="score a finished run: ATE, mesh metrics against a GT mesh, report.md",
        description=(
            "ATE (all statistics) of RUN_DIR; with --gt-mesh also culling of both meshes "
            "(--protocol), accuracy, completion, completion ratio, precision/recall/F1 "
            "and depth L1. Adds to metrics.json, writes mesh_culled.ply, report.md and "
            "two plots (needs the [eval] and [viz] extras)."
        ),
    )
    evaluation.add_argument("run_dir", metavar="RUN_DIR", help="a finished run folder")
    evaluation.add_argument("--gt-mesh", help="ground-truth mesh in the poses' world frame")
    evaluation.add_argument(
        "--data", metavar="PATH", help="the run's sequence, where it moved (default: config.yaml's)"
    )
    evaluation.add_argument(
        "--protocol", choices=("eslam", "nice"), default="eslam", help="culling (default eslam)"
    )
    evaluation.add_argument(
        "--samples", type=positive_int, default=450_000, help="samples per mesh (default 450000)"
    )
    evaluation.add_argument("--exact", action="store_true", help="point-to-surface distances")
    evaluation.add_argument(
        "--views",
        type=non_negative_int,
        default=1000,
        help="depth-L1 virtual views; 0 = skip (1000)",
    )
    evaluation.add_argument("--seed", type=int, default=0, help="samples and views (0)")
    evaluation.add_argument(
        "--cull-every", type=positive_int, default=1, help="cull with every k-th frame (1)"
    )
    evaluation.add_argument(
        "--max-unobserved",
        type=float,
        default=0.0,
        help="share of a view's pixels that may see unobserved space (0, the release)",
    )
    evaluation.add_argument(
        "--device", default="cpu", help="device for culling: auto, cpu, cuda, cuda:N or mps (cpu)"
    )
    evaluation.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Evaluate the run (metrics.json, report.md); print the metrics."""
    from eslam.evaluate.report import metrics_text
    from eslam.workflows.evaluate_run import EvaluationOptions, evaluate_run

    options = EvaluationOptions(
        gt_mesh=Path(args.gt_mesh).absolute() if args.gt_mesh else None,
        protocol=args.protocol,
        samples=args.samples,
        exact=args.exact,
        depth_l1_views=args.views,
        seed=args.seed,
        cull_every=args.cull_every,
        max_unobserved_fraction=args.max_unobserved,
        device=args.device,
        data=Path(args.data).absolute() if args.data else None,
        progress=True,
    )
    metrics = evaluate_run(args.run_dir, options)
    print(f"wrote {Path(args.run_dir) / 'metrics.json'} and report.md")
    print(metrics_text(metrics))
    return 0
