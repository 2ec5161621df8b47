"""Exact closest points on triangles, vectorised (no sampling of the target surface).

The region test is the one of Ericson, "Real-Time Collision Detection" (2005), section
5.1.5: the closest point of a triangle to p lies in one of seven Voronoi regions (three
vertices, three edges, the face), told apart by dot products of p - vertex with the two
edge vectors. Written here for (N,) arrays of independent point/triangle pairs.
"""

from __future__ import annotations

import numpy as np

_DEGENERATE = 1e-30
"""Below this, a triangle's squared doubled area counts as zero (a segment or a point)."""


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", x, y)


def closest_point_on_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Closest point of each segment [a, b] to each point.

    Args:
        points, a, b: (N, 3) float64.

    Returns:
        (N, 3) float64 closest points; a zero-length segment gives ``a``.
    """
    ab = b - a
    length2 = _dot(ab, ab)
    t = _dot(points - a, ab) / np.where(length2 > 0, length2, 1.0)
    return a + np.clip(t, 0.0, 1.0)[:, None] * ab


def closest_point_on_triangles(
    points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Closest point of triangle (a, b, c) to each point, row by row (Ericson 5.1.5).

    Args:
        points: (N, 3) float64 query points.
        a, b, c: (N, 3) float64 triangle corners, one triangle per point.

    Returns:
        (N, 3) float64 closest points on the (closed) triangles. Degenerate triangles
        (collinear corners) are handled as their three edges.
    """
    ab, ac = b - a, c - a
    ap, bp, cp = points - a, points - b, points - c
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        on_ab = a + (d1 / (d1 - d3))[:, None] * ab
        on_ac = a + (d2 / (d2 - d6))[:, None] * ac
        on_bc = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[:, None] * (c - b)
        total = va + vb + vc
        inside = a + (vb / total)[:, None] * ab + (vc / total)[:, None] * ac
    regions = [
        (d1 <= 0) & (d2 <= 0),  # vertex a
        (d3 >= 0) & (d4 <= d3),  # vertex b
        (d6 >= 0) & (d5 <= d6),  # vertex c
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge ab
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge ac
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),  # edge bc
    ]
    closest = inside
    for mask, value in reversed(list(zip(regions, [a, b, c, on_ab, on_ac, on_bc], strict=True))):
        closest = np.where(mask[:, None], value, closest)
    cross = np.cross(ab, ac)
    degenerate = (_dot(cross, cross) <= _DEGENERATE) | ~np.isfinite(closest).all(axis=1)
    if degenerate.any():
        closest[degenerate] = _closest_on_edges(
            points[degenerate], a[degenerate], b[degenerate], c[degenerate]
        )
    return closest


def _closest_on_edges(
    points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Nearest of the closest points on the three edges (for degenerate triangles)."""
    candidates = np.stack(
        [
            closest_point_on_segments(points, a, b),
            closest_point_on_segments(points, b, c),
            closest_point_on_segments(points, c, a),
        ]
    )
    distances = np.linalg.norm(candidates - points[None], axis=2)
    best = distances.argmin(axis=0)
    return candidates[best, np.arange(len(points))]


def point_triangle_distance(
    points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Euclidean distance from each point to its triangle (row by row), metres.

    Args:
        points, a, b, c: (N, 3) float64.

    Returns:
        (N,) float64 distances.
    """
    return np.linalg.norm(points - closest_point_on_triangles(points, a, b, c), axis=1)
