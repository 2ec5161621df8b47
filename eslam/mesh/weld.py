"""Welding marching-cubes pieces: one vertex per grid edge across block seams.

Marching cubes puts every vertex on a grid edge (two coordinates whole numbers of grid
steps) or on a grid point. Blocks that share a boundary plane both produce the vertices
on its edges; keying each vertex by its edge makes the pieces one connected mesh.
"""

from __future__ import annotations

import numpy as np

ON_GRID_TOLERANCE = 1e-4
"""A coordinate within this many grid steps of a whole number counts as on the grid line.
Vertices come from float32 marching cubes in block-local coordinates below ~10^3, whose
rounding error is ~10^-5 steps at most."""


def grid_edge_keys(vertices: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """(V,) int64 key of the grid edge (or grid point) each vertex lies on.

    Args:
        vertices: (V, 3) float64 positions in grid steps (global grid indices).
        shape: grid points along each axis.

    Returns:
        ``((i * ny + j) * nz + k) * 4 + axis`` with (i, j, k) the edge's lower point and
        axis 0-2 its direction, or axis 3 for a vertex on a grid point.
    """
    nearest = np.rint(vertices)
    on_line = np.abs(vertices - nearest) <= ON_GRID_TOLERANCE
    base = np.where(on_line, nearest, np.floor(vertices)).astype(np.int64)
    axis = np.where(on_line.all(1), 3, np.argmin(on_line, axis=1))
    return ((base[:, 0] * shape[1] + base[:, 1]) * shape[2] + base[:, 2]) * 4 + axis


def weld_vertices(
    vertices: np.ndarray, faces: np.ndarray, shape: tuple[int, int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices on the same grid edge; drop faces that collapse.

    Args:
        vertices: (V, 3) float64 positions in grid steps.
        faces: (F, 3) int vertex indices.
        shape: grid points along each axis.

    Returns:
        (V', 3) vertices (the first of each merged group, in key order) and (F', 3)
        int64 faces.
    """
    keys = grid_edge_keys(vertices, shape)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    faces = inverse.reshape(-1)[faces].astype(np.int64)
    valid = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
    valid &= faces[:, 2] != faces[:, 0]
    return vertices[first], faces[valid]
