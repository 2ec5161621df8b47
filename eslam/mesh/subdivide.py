"""Long-edge subdivision: split faces until no edge is longer than a threshold.

Used before culling (as Co-SLAM's evaluation does, ``subdivide_to_size`` with max_edge
1.5 cm) so that a large face half in view is not kept or dropped whole. A face with an
edge over the threshold is split 1-to-4 at its edge midpoints; midpoints are shared
between the split faces of an edge, colours are the mean of the edge's ends. Faces next
to a split face that are not split themselves keep their edge whole (a T-junction: the
surface has no gap, the mesh is no longer edge-manifold there).
"""

from __future__ import annotations

import numpy as np

from eslam.types import TriangleMesh

COSLAM_MAX_EDGE = 0.015
"""Co-SLAM's culling subdivides to edges of at most 1.5 cm (neural_slam_eval cull_mesh.py)."""

MAX_ROUNDS = 10
"""Split rounds at most (each halves the longest edges): 2^10 x the threshold is split."""


def _edge_lengths(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) lengths of edges (0, 1), (1, 2), (2, 0)."""
    corners = vertices[faces]
    return np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2)


def subdivide_long_edges(
    mesh: TriangleMesh, max_edge: float, max_rounds: int = MAX_ROUNDS
) -> TriangleMesh:
    """Split faces with an edge longer than ``max_edge`` metres, 1-to-4, repeatedly.

    Args:
        mesh: the mesh (unchanged).
        max_edge: the longest edge allowed, metres.
        max_rounds: split rounds at most.

    Returns:
        A new mesh covering the same surface; the original vertices keep their indices.
    """
    if not max_edge > 0:
        raise ValueError(f"max_edge must be > 0, got {max_edge}")
    vertices, faces = mesh.vertices, mesh.faces
    colours = mesh.colours.astype(np.float64)
    for _ in range(max_rounds):
        split = (_edge_lengths(vertices, faces) > max_edge).any(axis=1)
        if not split.any():
            break
        chosen = faces[split]
        edges = np.sort(
            np.concatenate([chosen[:, [0, 1]], chosen[:, [1, 2]], chosen[:, [2, 0]]]), 1
        )
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        midpoints = len(vertices) + inverse.reshape(3, -1)  # (3, S): edges 01, 12, 20
        vertices = np.concatenate([vertices, vertices[unique].mean(axis=1)])
        colours = np.concatenate([colours, colours[unique].mean(axis=1)])
        a, b, c = chosen.T
        ab, bc, ca = midpoints
        new = np.stack(
            [
                np.stack([a, ab, ca], 1),
                np.stack([ab, b, bc], 1),
                np.stack([ca, bc, c], 1),
                np.stack([ab, bc, ca], 1),
            ],
            axis=1,
        ).reshape(-1, 3)
        faces = np.concatenate([faces[~split], new])
    return TriangleMesh(
        vertices=vertices, faces=faces.astype(np.int64), colours=np.rint(colours).astype(np.uint8)
    )
