"""Triangle meshes with vertex colours: the one type and the PLY reader/writer eslam uses.

trimesh is always called with ``process=False`` so vertices keep their order and are
never merged (dependencies.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.atomic import write_with
from eslam.errors import InputError


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """A triangle mesh with vertex colours.

    Attributes:
        vertices: (V, 3) float64, metres.
        faces: (F, 3) int64 vertex indices.
        colours: (V, 3) uint8 RGB.
    """

    vertices: np.ndarray
    faces: np.ndarray
    colours: np.ndarray


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
