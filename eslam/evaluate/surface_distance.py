"""Exact point-to-mesh distance: KD-tree candidates with a provable radius, then exact maths.

Every triangle is cut (conceptually) into n x n similar sub-triangles ("pieces") so
that no piece reaches farther than ``piece_radius`` from its centroid; a KD-tree holds
the piece centroids. For a query point q:

1. Upper bound: the exact distance d1 from q to the triangle owning the nearest piece
   centroid (the true distance d* <= d1).
2. Candidates: every triangle owning a piece whose centroid lies within
   d1 + piece_radius of q. This is complete: the closest point x* of the surface lies
   in some piece P of its triangle, so |q - c_P| <= |q - x*| + |x* - c_P|
   <= d1 + piece_radius.
3. Exact closest-point-on-triangle distance to each candidate; the minimum is d*.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from eslam.evaluate.point_triangle import point_triangle_distance

_CHUNK = 32768
"""Query points per batch: bounds the memory of the candidate pairs."""
_MAX_PIECES_PER_TRIANGLE = 16
_MIN_PIECE_BUDGET = 1_000_000
"""Pieces allowed in all: max(16 per triangle, one million); beyond, pieces grow."""
_RADIUS_SLACK = 1e-9
"""Metres added to the search radius against rounding (the bound is exact in reals)."""


@dataclass(frozen=True, eq=False)
class SurfaceIndex:
    """A triangle mesh prepared for exact distance queries (see the module docstring).

    Attributes:
        triangles: (F, 3, 3) float64 corners, metres.
        tree: KD-tree over the (P, 3) piece centroids.
        piece_face: (P,) int64 triangle owning each piece.
        piece_radius: every point of a piece is within this of its centroid, metres.
    """

    triangles: np.ndarray
    tree: cKDTree
    piece_face: np.ndarray
    piece_radius: float


def _triangle_radius(triangles: np.ndarray) -> np.ndarray:
    centroid = triangles.mean(axis=1, keepdims=True)
    return np.linalg.norm(triangles - centroid, axis=2).max(axis=1)


def _piece_barycentrics(splits: int) -> np.ndarray:
    """(splits^2, 2) barycentric (along ab, along ac) centroids of the sub-triangles.

    A triangle with each edge cut into ``splits`` equal parts falls into splits^2
    sub-triangles, each similar to it at scale 1/splits: the "up" ones with corners
    (i, j), (i+1, j), (i, j+1) and the "down" ones with corners (i+1, j), (i, j+1),
    (i+1, j+1) in units of ab/splits and ac/splits.
    """
    i, j = np.meshgrid(np.arange(splits), np.arange(splits), indexing="ij")
    up = (i + j) <= splits - 1
    down = (i + j) <= splits - 2
    centroids = np.concatenate(
        [
            np.stack([i[up] + 1 / 3, j[up] + 1 / 3], axis=1),
            np.stack([i[down] + 2 / 3, j[down] + 2 / 3], axis=1),
        ]
    )
    return centroids / splits


def build_surface_index(
    vertices: np.ndarray, faces: np.ndarray, piece_radius: float | None = None
) -> SurfaceIndex:
    """Prepare a mesh for :func:`distance_to_surface`.

    Args:
        vertices: (V, 3) float, metres.
        faces: (F, 3) int vertex indices, F >= 1.
        piece_radius: the largest reach of a piece, metres; default the median
            triangle radius (most triangles stay whole, large ones are cut up). It is
            raised when it would need more than max(16 F, 10^6) pieces.

    Returns:
        The index.
    """
    triangles = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    if triangles.ndim != 3 or len(triangles) == 0:
        raise ValueError("need at least one triangle")
    radius = _triangle_radius(triangles)
    if piece_radius is None:
        piece_radius = float(np.median(radius))
    piece_radius = max(piece_radius, 1e-12)
    limit = max(_MAX_PIECES_PER_TRIANGLE * len(triangles), _MIN_PIECE_BUDGET)
    splits = np.maximum(np.ceil(radius / piece_radius), 1)
    while np.sum(splits**2) > limit:  # a tiny radius on large triangles: coarsen
        piece_radius *= 1.5
        splits = np.maximum(np.ceil(radius / piece_radius), 1)
    splits = splits.astype(np.int64)
    centroids, owners = [], []
    for count in np.unique(splits):
        chosen = np.flatnonzero(splits == count)
        weights = _piece_barycentrics(int(count))  # (K, 2)
        corner = triangles[chosen, 0]
        ab = triangles[chosen, 1] - corner
        ac = triangles[chosen, 2] - corner
        points = (
            corner[:, None]
            + weights[None, :, :1] * ab[:, None]
            + weights[None, :, 1:] * ac[:, None]
        )
        centroids.append(points.reshape(-1, 3))
        owners.append(np.repeat(chosen, len(weights)))
    return SurfaceIndex(
        triangles=triangles,
        tree=cKDTree(np.concatenate(centroids)),
        piece_face=np.concatenate(owners),
        piece_radius=float(piece_radius),
    )


def _distances_to_faces(index: SurfaceIndex, points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    corners = index.triangles[faces]
    return point_triangle_distance(points, corners[:, 0], corners[:, 1], corners[:, 2])


def _chunk_distances(index: SurfaceIndex, points: np.ndarray) -> np.ndarray:
    _, nearest = index.tree.query(points, k=1, workers=-1)
    upper = _distances_to_faces(index, points, index.piece_face[nearest])
    radii = upper + index.piece_radius + _RADIUS_SLACK
    lists = index.tree.query_ball_point(points, radii, workers=-1, return_sorted=False)
    counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
    pieces = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.int64, count=counts.sum())
    query = np.repeat(np.arange(len(points), dtype=np.int64), counts)
    face_count = len(index.triangles)
    keys = np.unique(query * face_count + index.piece_face[pieces])
    query, faces = keys // face_count, keys % face_count
    distances = _distances_to_faces(index, points[query], faces)
    best = upper.copy()
    if len(query) == 0:
        return best
    starts = np.flatnonzero(np.r_[True, query[1:] != query[:-1]])
    best[query[starts]] = np.minimum(upper[query[starts]], np.minimum.reduceat(distances, starts))
    return best


def distance_to_surface(index: SurfaceIndex, points: np.ndarray) -> np.ndarray:
    """Exact Euclidean distance from each point to the mesh surface.

    Args:
        index: from :func:`build_surface_index`.
        points: (N, 3) float, metres.

    Returns:
        (N,) float64 distances, metres.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.empty(len(points))
    for start in range(0, len(points), _CHUNK):
        out[start : start + _CHUNK] = _chunk_distances(index, points[start : start + _CHUNK])
    return out
