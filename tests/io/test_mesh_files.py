"""Mesh inputs of the evaluation commands: files and run folders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.errors import InputError
from eslam.io.mesh_files import find_mesh, read_mesh, write_mesh_ply
from eslam.types import TriangleMesh


def _triangle(offset: float) -> TriangleMesh:
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64) + offset
    return TriangleMesh(vertices, np.array([[0, 1, 2]]), np.full((3, 3), 200, np.uint8))


def test_a_run_folder_stands_for_its_culled_mesh_else_its_mesh(tmp_path: Path) -> None:
    write_mesh_ply(tmp_path / "mesh.ply", _triangle(0.0))
    assert find_mesh(tmp_path) == tmp_path / "mesh.ply"
    write_mesh_ply(tmp_path / "mesh_culled.ply", _triangle(5.0))
    assert find_mesh(tmp_path) == tmp_path / "mesh_culled.ply"
    np.testing.assert_allclose(read_mesh(tmp_path).vertices, _triangle(5.0).vertices)
    assert find_mesh(tmp_path / "mesh.ply") == tmp_path / "mesh.ply"


def test_mesh_errors_name_the_path(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"holds no mesh_culled\.ply or mesh\.ply"):
        find_mesh(tmp_path)
    with pytest.raises(InputError, match=r"nothing\.ply: not found"):
        read_mesh(tmp_path / "nothing.ply")
    (tmp_path / "broken.ply").write_text("ply\nthis is not a mesh\n")
    with pytest.raises(InputError, match=r"broken\.ply"):
        read_mesh(tmp_path / "broken.ply")
