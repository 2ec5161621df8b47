"""``eslam recon``: accuracy / completion / ratio / F1 (and depth L1) of a mesh against a
ground-truth mesh."""

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
    from eslam.errors import ConfigError, InputError
    from eslam.evaluate.depth_l1 import DepthL1Options, depth_l1
    from eslam.evaluate.reconstruction import ReconstructionOptions, evaluate_reconstruction
    from eslam.evaluate.report import titled_table
    from eslam.io.mesh_files import find_mesh, read_mesh
    from eslam.io.run_dir import json_text

    rec_path, gt_path = find_mesh(args.rec), find_mesh(args.gt)
    reconstruction, ground_truth = read_mesh(rec_path), read_mesh(gt_path)
    options = ReconstructionOptions(samples=args.samples, seed=args.seed, exact=args.exact)
    try:
        metrics: dict[str, object] = evaluate_reconstruction(
            reconstruction, ground_truth, options
        ).as_dict()
    except ValueError as error:
        raise InputError(rec_path, str(error), "check both meshes have triangles") from None
    if args.depth_l1:
        uncut = read_mesh(args.gt_uncut) if args.gt_uncut else None
        depth_options = DepthL1Options(views=args.views, seed=args.seed)
        try:
            metrics.update(depth_l1(reconstruction, ground_truth, depth_options, uncut).as_dict())
        except ImportError as error:
            raise ConfigError(f"--depth-l1: {error}") from None
    if args.json:
        print(json_text({**metrics, "rec": rec_path, "gt": gt_path}))
    else:
        print(titled_table(f"reconstruction {rec_path} against {gt_path}", metrics))
    return 0
