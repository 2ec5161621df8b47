"""Mesh inputs of the evaluation commands: a mesh file, or a run folder holding one."""

from __future__ import annotations

from pathlib import Path

from eslam.data.mesh_io import TriangleMesh, read_mesh_ply
from eslam.errors import InputError
from eslam.io.run_dir import RunDirectory


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
