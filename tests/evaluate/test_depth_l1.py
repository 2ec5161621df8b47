"""Ray-cast depth and depth L1 on scenes with analytic answers (planes and spheres)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from eslam.evaluate.depth_l1 import (
    DepthL1Options,
    camera_box,
    depth_l1,
    draw_camera,
    look_at,
    unobserved_pixels,
    view_error,
)
from eslam.evaluate.raycast import MeshRaycaster, pixel_rays
from eslam.types import Intrinsics, TriangleMesh

CENTRE = np.array([0.5, -1.0, 1.2])
RADIUS = 2.0


def _mesh(vertices: np.ndarray, faces: np.ndarray) -> TriangleMesh:
    vertices = np.asarray(vertices, dtype=np.float64)
    return TriangleMesh(vertices, np.asarray(faces), np.zeros((len(vertices), 3), np.uint8))


def _sphere(radius: float, centre: np.ndarray = CENTRE) -> TriangleMesh:
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    return _mesh(np.asarray(mesh.vertices) + centre, mesh.faces)


def test_a_tilted_plane_renders_its_analytic_depth() -> None:
    """Plane n . X = d in camera axes; the pixel ray (x, y, 1) hits it at z = d / (n . ray)."""
    intrinsics = Intrinsics(width=40, height=30, fx=35.0, fy=30.0, cx=19.5, cy=14.5)
    normal = np.array([0.2, -0.1, 1.0])
    offset = 2.0
    # a large square on that plane, in camera coordinates
    u = np.cross(normal, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal / np.linalg.norm(normal), u)
    centre = normal * offset / (normal @ normal)
    corners = [centre + 10 * (sx * u + sy * v) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    pose = look_at(np.array([1.0, 2.0, 3.0]), np.array([0.3, 1.0, -0.2]), np.array([0, 0, -1.0]))
    world = np.asarray(corners) @ pose[:3, :3].T + pose[:3, 3]
    plane = _mesh(world, [[0, 1, 2], [0, 2, 3]])
    depth = MeshRaycaster(plane.vertices, plane.faces).depth(pose, intrinsics)
    rays = pixel_rays(intrinsics)
    expected = (offset / (rays @ normal)).reshape(intrinsics.height, intrinsics.width)
    assert depth.shape == (30, 40)
    np.testing.assert_allclose(depth, expected, rtol=1e-5)


def test_misses_and_surfaces_behind_the_camera_have_no_depth() -> None:
    intrinsics = Intrinsics(width=8, height=8, fx=8.0, fy=8.0, cx=3.5, cy=3.5)
    behind = _mesh([[-5, -5, -1], [5, -5, -1], [0, 5, -1]], [[0, 1, 2]])
    depth = MeshRaycaster(behind.vertices, behind.faces).depth(np.eye(4), intrinsics)
    assert np.all(depth == 0.0)


def test_look_at_is_a_rotation_looking_at_the_target() -> None:
    pose = look_at(np.zeros(3), np.array([1.0, 2.0, 0.5]), np.array([0.0, 0.0, -1.0]))
    rotation = pose[:3, :3]
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(rotation[:, 2], np.array([1.0, 2.0, 0.5]) / np.sqrt(5.25))
    assert rotation[:, 0] @ [0.0, 0.0, 1.0] == pytest.approx(0.0, abs=1e-12)  # x is level
    assert look_at(np.zeros(3), np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, -1.0])) is None


def test_camera_box_follows_the_release() -> None:
    """For an axis-aligned 2 x 4 x 6 box the sorted extents scale to 0.6, 2.8, 4.2."""
    box = trimesh.creation.box(extents=[4.0, 6.0, 2.0])
    gt = _mesh(np.asarray(box.vertices) + np.ones(3), box.faces)
    region = camera_box(gt)
    np.testing.assert_allclose(region.extents, [0.6, 2.8, 4.2], atol=1e-9)
    np.testing.assert_allclose(region.transform[:3, 3], [1.0, 1.0, 1.4], atol=1e-9)
    rng = np.random.default_rng(0)
    origins = np.array([draw_camera(region, rng)[:3, 3] for _ in range(500)])
    np.testing.assert_allclose(origins.min(axis=0), [-0.4, -1.1, 1.1], atol=0.05)
    np.testing.assert_allclose(origins.max(axis=0), [2.4, 3.1, 1.7], atol=0.05)


def test_view_error_rules() -> None:
    gt = np.array([[1.0, 2.0], [0.0, 3.0]])
    rec = np.array([[1.5, 0.0], [0.0, 2.0]])
    assert view_error(gt, rec, count_missing=False) == pytest.approx(0.75)
    assert view_error(gt, rec, count_missing=True) == pytest.approx((0.5 + 2.0 + 1.0) / 4)
    assert view_error(gt, np.zeros_like(gt), count_missing=False) is None


def test_unobserved_pixels() -> None:
    full = np.array([[1.0, 1.0, 2.0, 0.0]])
    culled = np.array([[1.0, 0.0, 3.0, 0.0]])  # kept, culled to nothing, culled to farther
    assert unobserved_pixels(culled, full, tolerance_m=1e-3).sum() == 2
    assert unobserved_pixels(full, full, tolerance_m=1e-3).sum() == 0


def test_depth_l1_of_a_mesh_against_itself_is_zero() -> None:
    room = _sphere(RADIUS)
    result = depth_l1(room, room, DepthL1Options(views=5, width=64, height=48, focal=40.0))
    assert result.depth_l1_cm == 0.0
    assert result.views_used == 5 and result.views_rejected == 0


def test_depth_l1_against_a_sphere_two_centimetres_larger() -> None:
    """Inside concentric spheres every pixel hits both; the gap along a ray is analytic.

    A ray o + t d (|d| = 1) leaves a sphere of radius r at t = -b + sqrt(b^2 - c),
    b = d . (o - m), c = |o - m|^2 - r^2; depth is t times the cosine to the optical axis.
    """
    options = DepthL1Options(views=4, width=64, height=48, focal=40.0, seed=3)
    gt, rec = _sphere(RADIUS), _sphere(RADIUS + 0.02)
    result = depth_l1(rec, gt, options)
    # replay the same cameras and compute the depth gap of ideal spheres
    rng = np.random.default_rng(options.seed)
    region = camera_box(gt)
    rays = pixel_rays(options.intrinsics())
    expected = []
    for _ in range(options.views):
        pose = draw_camera(region, rng)
        unit = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        directions = unit @ pose[:3, :3].T
        offset = pose[:3, 3] - CENTRE
        assert offset @ offset < (RADIUS - 0.05) ** 2  # the formula needs the camera inside
        b = directions @ offset

        def exit_distance(r: float, b: np.ndarray = b, offset: np.ndarray = offset) -> np.ndarray:
            return -b + np.sqrt(b**2 - (offset @ offset - r**2))

        gap = (exit_distance(RADIUS + 0.02) - exit_distance(RADIUS)) * unit[:, 2]
        expected.append(gap.mean())
    assert result.views_used == 4
    assert result.depth_l1_cm == pytest.approx(100 * np.mean(expected), abs=0.02)
    assert 1.7 < result.depth_l1_cm < 2.3


def test_views_of_culled_space_are_redrawn() -> None:
    full = _sphere(RADIUS)
    keep = (full.vertices[full.faces][:, :, 2] < CENTRE[2] + 0.5).all(axis=1)
    culled = TriangleMesh(full.vertices, full.faces[keep], full.colours)
    options = DepthL1Options(views=6, width=32, height=32, focal=20.0, seed=1)
    result = depth_l1(culled, culled, options, ground_truth_uncut=full)
    assert result.views_used == 6 and result.views_rejected > 0
    assert result.depth_l1_cm == 0.0
    # without the uncut mesh, views of the hole are kept; a hole-free reconstruction is
    # scored only where the culled GT has depth, where both see the same surface
    free = depth_l1(full, culled, options)
    assert free.views_used == 6 and free.views_rejected < result.views_rejected
    assert free.depth_l1_cm == 0.0


def test_options_are_checked_and_release_defaults() -> None:
    options = DepthL1Options()
    assert (options.views, options.width, options.height, options.focal) == (1000, 500, 500, 300)
    assert (options.intrinsics().cx, options.intrinsics().cy) == (249.5, 249.5)
    with pytest.raises(ValueError):
        DepthL1Options(views=0)


def test_view_error_leaves_out_pixels_that_see_unobserved_space() -> None:
    gt = np.full((2, 2), 2.0)
    rec = np.array([[2.0, 2.0], [2.0, 3.0]])  # off by 1 m where the GT was culled away
    unobserved = np.array([[False, False], [False, True]])
    assert view_error(gt, rec, count_missing=False) == 0.25
    assert view_error(gt, rec, count_missing=False, scored=~unobserved) == 0.0
    assert view_error(gt, rec, count_missing=False, scored=np.zeros((2, 2), bool)) is None
