"""Seeded, area-weighted points on a triangle mesh surface."""

from __future__ import annotations

import numpy as np


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) float64 triangle areas, square metres, of ``vertices`` (V, 3) and ``faces`` (F, 3)."""
    corners = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return 0.5 * np.linalg.norm(cross, axis=1)


def sample_surface(
    vertices: np.ndarray, faces: np.ndarray, count: int, rng: np.random.Generator
) -> np.ndarray:
    """``count`` points uniformly distributed over the surface (area-weighted).

    A triangle is drawn with probability proportional to its area, then a point in
    it with the square-root rule of Osada et al., "Shape distributions" (TOG 2002):
    p = (1 - sqrt(r1)) a + sqrt(r1) (1 - r2) b + sqrt(r1) r2 c, r1, r2 ~ U[0, 1).

    Args:
        vertices: (V, 3) float, metres.
        faces: (F, 3) int vertex indices.
        count: number of points.
        rng: the seeded generator every random number comes from.

    Returns:
        (count, 3) float64 points, metres.

    Raises:
        ValueError: the mesh has no triangle of positive area.
    """
    areas = triangle_areas(vertices, faces)
    total = float(areas.sum()) if len(areas) else 0.0
    if not total > 0:
        raise ValueError("the mesh has no surface (no triangle of positive area)")
    cumulative = np.cumsum(areas)
    chosen = np.searchsorted(cumulative, rng.random(count) * cumulative[-1], side="right")
    chosen = np.minimum(chosen, len(areas) - 1)
    corners = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)[chosen]]
    root = np.sqrt(rng.random(count))[:, None]
    second = rng.random(count)[:, None]
    return (
        (1.0 - root) * corners[:, 0]
        + root * (1.0 - second) * corners[:, 1]
        + root * second * corners[:, 2]
    )
