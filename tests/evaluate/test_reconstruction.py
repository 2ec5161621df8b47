"""Reconstruction metrics on meshes with known answers: displaced, partial and identical."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from eslam.evaluate.reconstruction import (
    ReconstructionOptions,
    SampleDistances,
    evaluate_reconstruction,
    metrics_from_distances,
)
from eslam.evaluate.sampling import sample_surface, triangle_areas
from eslam.types import TriangleMesh

RADIUS = 0.5


def _sphere(radius: float = RADIUS, subdivisions: int = 5) -> TriangleMesh:
    """Icosphere (20 * 4^s faces) centred at (1, 2, 3): about 1 cm triangles at s = 5."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    vertices = np.asarray(mesh.vertices) + np.array([1.0, 2.0, 3.0])
    colours = np.zeros((len(vertices), 3), dtype=np.uint8)
    return TriangleMesh(vertices, np.asarray(mesh.faces, dtype=np.int64), colours)


def _along_normals(mesh: TriangleMesh, offset: float) -> TriangleMesh:
    normals = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).vertex_normals
    return TriangleMesh(mesh.vertices + offset * np.asarray(normals), mesh.faces, mesh.colours)


def test_samples_lie_on_the_surface_area_weighted_and_seeded() -> None:
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 1], [8, 0, 1], [5, 2, 1]], float)
    faces = np.array([[0, 1, 2], [3, 4, 5]])  # areas 0.5 and 3
    np.testing.assert_allclose(triangle_areas(vertices, faces), [0.5, 3.0])
    points = sample_surface(vertices, faces, 70_000, np.random.default_rng(0))
    on_first = points[:, 2] == 0.0
    assert abs(on_first.mean() - 0.5 / 3.5) < 0.005
    first, second = points[on_first], points[~on_first]
    assert np.all(first[:, :2] >= 0) and np.all(first[:, 0] + first[:, 1] <= 1 + 1e-12)
    assert np.all(second[:, 1] >= 0) and np.all((second[:, 0] - 5) / 3 + second[:, 1] / 2 <= 1)
    # uniform inside a triangle: the mean is the centroid
    np.testing.assert_allclose(first[:, :2].mean(axis=0), [1 / 3, 1 / 3], atol=0.005)
    again = sample_surface(vertices, faces, 70_000, np.random.default_rng(0))
    np.testing.assert_array_equal(points, again)


def test_sampling_needs_area() -> None:
    flat = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    with pytest.raises(ValueError, match="no surface"):
        sample_surface(flat, np.array([[0, 1, 2]]), 10, np.random.default_rng(0))


def test_one_centimetre_displacement_sampled_and_exact() -> None:
    gt = _sphere()
    rec = _along_normals(gt, 0.01)
    sampled = evaluate_reconstruction(rec, gt, ReconstructionOptions(samples=200_000))
    # the nearest sample of the other surface adds the sampling spacing (~0.4 cm here)
    assert 1.0 < sampled.accuracy_cm < 1.1 and 1.0 < sampled.completion_cm < 1.1
    assert sampled.completion_ratio_pct == 100.0 and not sampled.exact
    exact = evaluate_reconstruction(rec, gt, ReconstructionOptions(samples=50_000, exact=True))
    assert abs(exact.accuracy_cm - 1.0) < 0.05 and abs(exact.completion_cm - 1.0) < 0.05
    assert exact.samples == 50_000 and exact.exact


def test_a_mesh_against_itself_is_perfect_only_in_exact_mode() -> None:
    gt = _sphere()
    exact = evaluate_reconstruction(gt, gt, ReconstructionOptions(samples=20_000, exact=True))
    assert exact.accuracy_cm < 1e-10 and exact.completion_cm < 1e-10
    assert exact.completion_ratio_pct == 100.0 and exact.f1_pct == 100.0
    sampled = evaluate_reconstruction(gt, gt, ReconstructionOptions(samples=20_000))
    assert sampled.accuracy_cm > 0.3  # the sampling floor: ~1.2 cm spacing at 20k samples


@pytest.mark.parametrize(("offset", "expected"), [(0.005, 100.0), (0.015, 0.0)])
def test_precision_recall_f1_at_one_centimetre(offset: float, expected: float) -> None:
    gt = _sphere()
    result = evaluate_reconstruction(
        _along_normals(gt, offset), gt, ReconstructionOptions(samples=20_000, exact=True)
    )
    assert result.precision_pct == expected and result.recall_pct == expected
    assert result.f1_pct == expected


def test_completion_ratio_of_a_hemisphere() -> None:
    """GT points of the missing half closer than 5 cm to the rim: a band 5 cm deep.

    On a sphere area is uniform in height, and a point at polar angle theta below the
    rim is 2 R sin(theta / 2) from it, so the band reaches down R sin(0.1) (chord 5 cm
    at R = 0.5 m): ratio = 50 % + 50 % * sin(0.1) = 54.99 %.
    """
    gt = _sphere()
    centre = np.array([1.0, 2.0, 3.0])
    keep = (gt.vertices[gt.faces][:, :, 2] >= centre[2] - 1e-9).all(axis=1)
    rec = TriangleMesh(gt.vertices, gt.faces[keep], gt.colours)
    result = evaluate_reconstruction(rec, gt, ReconstructionOptions(samples=100_000, exact=True))
    assert result.accuracy_cm < 1e-10 and result.precision_pct == 100.0
    assert abs(result.completion_ratio_pct - (50.0 + 50.0 * np.sin(0.1))) < 0.5
    assert abs(result.recall_pct - (50.0 + 50.0 * np.sin(0.02))) < 0.5
    expected_f1 = 2 * 100.0 * result.recall_pct / (100.0 + result.recall_pct)
    assert abs(result.f1_pct - expected_f1) < 1e-9


def test_metrics_from_distances_and_keys() -> None:
    distances = SampleDistances(
        reconstruction_to_gt=np.array([0.0, 0.02, 0.005, 0.1]),
        gt_to_reconstruction=np.array([0.06, 0.0, 0.049]),
    )
    result = metrics_from_distances(distances, ReconstructionOptions(samples=3))
    assert result.as_dict() == pytest.approx(
        {
            "accuracy_cm": 3.125,
            "completion_cm": 3.6333333333,
            "completion_ratio_pct": 200 / 3,
            "precision_pct": 50.0,
            "recall_pct": 100 / 3,
            "f1_pct": 2 * 50 * (100 / 3) / (50 + 100 / 3),
            "samples": 3,
            "exact": False,
        }
    )


def test_bad_options_and_meshes() -> None:
    with pytest.raises(ValueError):
        ReconstructionOptions(samples=0)
    empty = TriangleMesh(np.zeros((3, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no triangles"):
        evaluate_reconstruction(empty, _sphere(subdivisions=1), ReconstructionOptions(samples=10))
