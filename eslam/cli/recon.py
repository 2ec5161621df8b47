"""``eslam recon``: accuracy / completion / ratio / F1 (and depth L1) of a mesh against a
ground-truth mesh.

The errors come from :func:`eslam.workflows.reconstruction_metrics.mesh_errors`; this
module parses the arguments and prints the table or JSON.
"""

from __future__ import annotations

import argparse

from eslam.cli.args import positive_int


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``recon`` to ``commands``."""
    from eslam.evaluate.depth_l1 import RELEASE_VIEWS
    from eslam.evaluate.reconstruction import RELEASE_SAMPLES

    recon = commands.add_parser(
        "recon",
        help="accuracy / completion / ratio / F1 (and depth L1) of a mesh against a GT mesh",
        description=(
            "Sample both meshes (area-weighted, seeded) and measure accuracy (rec to GT), "
            "completion (GT to rec), completion ratio (< 5 cm), precision / recall / F1 "
            "(< 1 cm). REC and GT are mesh files or run folders (mesh_culled.ply, else "
            "mesh.ply). --exact measures distances to the other mesh's triangles instead of "
            "its samples; --depth-l1 adds the depth L1 over random virtual views."
        ),
    )
    recon.add_argument("rec", metavar="REC", help="reconstructed mesh or run folder")
    recon.add_argument("gt", metavar="GT", help="ground-truth mesh or run folder")
    recon.add_argument("--exact", action="store_true", help="distances to the other surface")
    recon.add_argument(
        "--samples",
        type=positive_int,
        default=RELEASE_SAMPLES,
        metavar="N",
        help=f"points sampled per mesh (default {RELEASE_SAMPLES}, the ESLAM protocol)",
    )
    recon.add_argument("--seed", type=int, default=0, help="seed of samples and views")
    recon.add_argument("--depth-l1", action="store_true", help="also the depth L1 (slower)")
    recon.add_argument(
        "--views",
        type=positive_int,
        default=RELEASE_VIEWS,
        metavar="N",
        help=f"virtual views of the depth L1 (default {RELEASE_VIEWS})",
    )
    recon.add_argument(
        "--gt-uncut",
        metavar="PATH",
        help="the GT mesh before culling: depth L1 views that see culled-away space are redrawn",
    )
    recon.add_argument("--json", action="store_true", help="print JSON instead of a table")
    recon.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Print the mesh errors as a table, or as JSON with both mesh files."""
    from eslam.evaluate.report import titled_table
    from eslam.io.run_dir import json_text
    from eslam.workflows.reconstruction_metrics import mesh_errors

    result = mesh_errors(
        args.rec,
        args.gt,
        samples=args.samples,
        seed=args.seed,
        exact=args.exact,
        depth_l1=args.depth_l1,
        views=args.views,
        gt_uncut=args.gt_uncut,
    )
    metrics = result.as_dict()
    if args.json:
        print(json_text({**metrics, "rec": result.rec, "gt": result.gt}))
    else:
        print(titled_table(f"reconstruction {result.rec} against {result.gt}", metrics))
    return 0
