"""Mesh files: PLY writing, reading any mesh file, and the mesh a run folder stands for.

trimesh is always called with ``process=False`` so vertices keep their order and are
never merged: a mesh read back is the mesh written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eslam.atomic import write_with
from eslam.errors import InputError
from eslam.io.run_dir import RunDirectory
from eslam.types import TriangleMesh


def write_mesh_ply(path: str | Path, mesh: TriangleMesh) -> None:
    """Write ``mesh`` as a binary PLY with vertex colours (atomically)."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=mesh.colours, process=False)
    write_with(path, lambda tmp: tm.export(tmp, file_type="ply", encoding="binary"))


def read_mesh_ply(path: str | Path) -> TriangleMesh:
    """Read a triangle mesh (PLY, OBJ, ... anything trimesh reads) without reordering it."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "mesh file not found")
    try:
        tm = trimesh.load(path, process=False, force="mesh")
    except Exception as error:  # trimesh raises many kinds on a broken file
        raise InputError(path, f"unreadable mesh ({error})") from None
    colours = np.zeros((len(tm.vertices), 3), dtype=np.uint8)
    visual = getattr(tm, "visual", None)
    if visual is not None and getattr(visual, "kind", None) == "vertex":
        colours = np.asarray(visual.vertex_colors)[:, :3].astype(np.uint8)
    return TriangleMesh(
        vertices=np.asarray(tm.vertices, dtype=np.float64),
        faces=np.asarray(tm.faces, dtype=np.int64),
        colours=colours,
    )


def find_mesh(path: str | Path) -> Path:
    """The mesh file ``path`` stands for.

    A file is itself. A run folder stands for its ``mesh_culled.ply`` when present (the
    mesh the paper's protocol scores), else its ``mesh.ply``.

    Raises:
        InputError: ``path`` does not exist, or is a folder without either mesh.
    """
    path = Path(path)
    if path.is_dir():
        run = RunDirectory(path)
        for candidate in (run.mesh_culled, run.mesh):
            if candidate.is_file():
                return candidate
        raise InputError(
            path,
            f"holds no {run.mesh_culled.name} or {run.mesh.name}",
            "pass a mesh file or a run folder with a mesh",
        )
    if not path.exists():
        raise InputError(path, "not found", "pass a mesh file (.ply, .obj) or a run folder")
    return path


def read_mesh(path: str | Path) -> TriangleMesh:
    """Read the mesh of a file or run folder (see :func:`find_mesh`).

    Raises:
        InputError: no such mesh, an unreadable file, or a mesh without triangles.
    """
    mesh_path = find_mesh(path)
    mesh = read_mesh_ply(mesh_path)
    if len(mesh.faces) == 0:
        raise InputError(mesh_path, "holds no triangles", "pass a triangle mesh")
    return mesh
