"""Exact point-to-triangle and point-to-mesh distance against slow, independent references."""

from __future__ import annotations

import numpy as np
import pytest

from eslam.evaluate.point_triangle import closest_point_on_triangles, point_triangle_distance
from eslam.evaluate.surface_distance import build_surface_index, distance_to_surface


def _segment_distance(p: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    d = y - x
    length2 = np.maximum(np.sum(d * d, axis=1), 1e-300)
    t = np.clip(np.sum((p - x) * d, axis=1) / length2, 0.0, 1.0)
    return np.linalg.norm(p - (x + t[:, None] * d), axis=1)


def _reference_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Plane distance when the foot of the perpendicular is inside, else nearest edge."""
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=1)
    flat = length == 0  # repeated corners: only the edges count
    length[flat] = 1.0
    height = np.sum((p - a) * normal, axis=1) / length
    foot = p - height[:, None] * normal / length[:, None]
    # the foot is inside when it is on the inner side of all three edges
    inside = ~flat
    for x, y in ((a, b), (b, c), (c, a)):
        inside &= np.sum(np.cross(y - x, foot - x) * normal, axis=1) >= 0
    edges = np.minimum.reduce(
        [_segment_distance(p, a, b), _segment_distance(p, b, c), _segment_distance(p, c, a)]
    )
    return np.where(inside, np.abs(height), edges)


def test_point_triangle_distance_matches_the_reference_in_every_region() -> None:
    rng = np.random.default_rng(0)
    p, a, b, c = (rng.normal(size=(100_000, 3)) for _ in range(4))
    np.testing.assert_allclose(
        point_triangle_distance(p, a, b, c), _reference_distance(p, a, b, c), atol=1e-12
    )


def test_closest_point_is_on_the_triangle_and_cases_are_exact() -> None:
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    cases = {
        (0.2, 0.2, 0.5): (0.2, 0.2, 0.0),  # face
        (-1.0, -1.0, 0.0): (0.0, 0.0, 0.0),  # vertex a
        (2.0, -0.5, 1.0): (1.0, 0.0, 0.0),  # vertex b
        (0.5, -2.0, 0.0): (0.5, 0.0, 0.0),  # edge ab
        (1.0, 1.0, -3.0): (0.5, 0.5, 0.0),  # edge bc
        (-1.0, 0.5, 0.0): (0.0, 0.5, 0.0),  # edge ca
    }
    for point, expected in cases.items():
        closest = closest_point_on_triangles(np.array([point]), a, b, c)
        np.testing.assert_allclose(closest[0], expected, atol=1e-15)


def test_degenerate_triangles_are_their_edges() -> None:
    p = np.array([[0.5, 1.0, 0.0], [3.0, 0.0, 0.0]])
    a = np.zeros((2, 3))
    b = np.array([[1.0, 0, 0], [0.0, 0, 0]])  # collinear corners; then a single point
    c = np.array([[2.0, 0, 0], [0.0, 0, 0]])
    np.testing.assert_allclose(point_triangle_distance(p, a, b, c), [1.0, 3.0], atol=1e-15)


def _brute_force(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    corners = vertices[faces]
    out = np.empty(len(points))
    for i, point in enumerate(points):
        repeated = np.repeat(point[None], len(faces), axis=0)
        out[i] = _reference_distance(repeated, corners[:, 0], corners[:, 1], corners[:, 2]).min()
    return out


@pytest.mark.parametrize(
    ("seed", "piece_radius"), [(1, None), (2, 0.05), (3, 10.0), (4, 0.02), (6, 1e-6)]
)
def test_mesh_distance_equals_brute_force(seed: int, piece_radius: float | None) -> None:
    rng = np.random.default_rng(seed)
    vertices = rng.uniform(size=(200, 3))
    # a mix of small and very large (sliver) triangles: the search radius must cover both
    faces = np.concatenate([rng.integers(0, 200, size=(300, 3)), [[0, 1, 2], [3, 4, 5]]])
    vertices[:6] *= 4.0
    index = build_surface_index(vertices, faces, piece_radius)
    points = np.concatenate([rng.uniform(-1.0, 2.0, size=(1500, 3)), vertices[:50]])
    exact = distance_to_surface(index, points)
    np.testing.assert_allclose(exact, _brute_force(points, vertices, faces), rtol=0, atol=1e-12)
    assert np.all(exact[-50:] < 1e-12)  # the vertices themselves


def test_points_on_the_surface_have_zero_distance() -> None:
    rng = np.random.default_rng(5)
    vertices = rng.normal(size=(100, 3))
    faces = rng.integers(0, 100, size=(150, 3))
    weights = rng.dirichlet(np.ones(3), size=150)
    points = np.einsum("fk,fkd->fd", weights, vertices[faces])
    assert distance_to_surface(build_surface_index(vertices, faces), points).max() < 1e-12
