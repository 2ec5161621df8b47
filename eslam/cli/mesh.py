"""``eslam mesh``: extract a run's mesh.ply again from its map.pt."""

from __future__ import annotations

import argparse

from eslam.cli.args import positive_float


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``mesh`` to ``commands``."""
    mesh = commands.add_parser(
        "mesh",
        help="extract RUN_DIR/mesh.ply again from the run's map.pt",
        description=(
            "Marching cubes of the saved field over the space the keyframes observed; "
            "replaces RUN_DIR/mesh.ply (atomically)."
        ),
    )
    mesh.add_argument("run_dir", metavar="RUN_DIR", help="folder of a run (config.yaml, map.pt)")
    mesh.add_argument(
        "--resolution",
        type=positive_float,
        metavar="M",
        help="grid step in metres (default: the run's output.mesh_resolution)",
    )
    mesh.add_argument(
        "--device", default="cpu", help="auto, cpu, cuda, cuda:N or mps (default cpu)"
    )
    mesh.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Re-extract the mesh; print its size and the time it took."""
    from eslam.slam.run.remesh import remesh_run

    result = remesh_run(args.run_dir, resolution=args.resolution, device=args.device)
    print(
        f"wrote {result.path} ({result.vertices} vertices, {result.faces} faces, "
        f"{result.resolution:g} m grid, {result.seconds:.1f} s)"
    )
    return 0
