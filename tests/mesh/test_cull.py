"""Culling protocols (ESLAM: frustum + occlusion, NICE-SLAM: frustum) and subdivision."""

from __future__ import annotations

import numpy as np
import pytest

from eslam.errors import ConfigError
from eslam.mesh.cull import CullCameras, CullOptions, cull_mesh, visible_vertices
from eslam.mesh.subdivide import subdivide_long_edges
from eslam.types import Intrinsics, TriangleMesh

CAMERA = Intrinsics(width=64, height=48, fx=40.0, fy=40.0, cx=31.5, cy=23.5)
WALL_DEPTH = 2.0


def _box(centre: tuple[float, float, float], half: float, colour: int) -> TriangleMesh:
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    faces = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )  # fmt: skip
    return TriangleMesh(
        vertices=np.array(centre) + half * corners,
        faces=faces,
        colours=np.full((8, 3), colour, dtype=np.uint8),
    )


def _wall(half: float) -> TriangleMesh:
    """A square at z = WALL_DEPTH facing the camera at the origin, larger than the view."""
    vertices = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
    vertices = np.column_stack([vertices, np.full(4, WALL_DEPTH)])
    return TriangleMesh(
        vertices=vertices,
        faces=np.array([[0, 1, 2], [0, 2, 3]]),
        colours=np.full((4, 3), 200, dtype=np.uint8),
    )


def _join(*meshes: TriangleMesh) -> TriangleMesh:
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return TriangleMesh(
        vertices=np.concatenate([m.vertices for m in meshes]),
        faces=np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=True)]),
        colours=np.concatenate([m.colours for m in meshes]),
    )


def _cameras(frames: int = 3) -> CullCameras:
    """Cameras at the origin looking along +z (slightly shifted), seeing only the wall."""
    poses = np.repeat(np.eye(4)[None], frames, axis=0)
    poses[:, 0, 3] = np.linspace(-0.05, 0.05, frames)
    depths = (np.full((CAMERA.height, CAMERA.width), WALL_DEPTH) for _ in range(frames))
    return CullCameras(poses=poses, intrinsics=CAMERA, depths=depths)


HIDDEN = _box((0.0, 0.0, 3.0), 0.2, 10)  # in the frustum, behind the wall
OUTSIDE = _box((0.0, 0.0, -1.5), 0.2, 20)  # behind the camera
SIDE = _box((5.0, 0.0, 1.0), 0.2, 30)  # beside the frustum
WALL = _wall(3.0)  # its corners are out of view; only subdivided pieces are seen


def _has(mesh: TriangleMesh, colour: int) -> bool:
    return bool((mesh.colours[:, 0] == colour).any())


def test_eslam_culls_the_occluded_box_nice_keeps_it() -> None:
    scene = _join(WALL, HIDDEN, OUTSIDE, SIDE)
    options = CullOptions(truncation=0.06, max_edge=0.25)
    eslam = cull_mesh(scene, _cameras(), "eslam", options)
    nice = cull_mesh(scene, _cameras(), "nice", options)
    assert not _has(eslam, 10) and _has(nice, 10), "hidden box: ESLAM culls, NICE keeps"
    for mesh in (eslam, nice):
        assert not _has(mesh, 20) and not _has(mesh, 30), "outside every frustum"
        wall = mesh.vertices[mesh.colours[:, 0] == 200]
        assert len(wall) > 0
        # the wall is cut to the frustum (half-width at z=2 is 1.6 m) plus one face
        assert np.abs(wall[:, 0]).max() < 1.65 + 0.25 and np.abs(wall[:, 1]).max() < 1.2 + 0.25
    assert len(eslam.faces) < len(nice.faces)
    # indices stay valid after unreferenced vertices are dropped
    assert eslam.faces.max() == len(eslam.vertices) - 1


def test_a_face_is_kept_when_any_vertex_is_seen() -> None:
    """The authors' rule: a wall whose four corners are out of view is culled whole,
    unless it is subdivided first."""
    assert len(cull_mesh(WALL, _cameras(), "nice").faces) == 0
    one_in_view = TriangleMesh(
        vertices=np.array([[0.0, 0.0, 2.0], [9.0, 0.0, 2.0], [0.0, 9.0, 2.0]]),
        faces=np.array([[0, 1, 2]]),
        colours=np.zeros((3, 3), dtype=np.uint8),
    )
    assert len(cull_mesh(one_in_view, _cameras(), "eslam").faces) == 1


def test_depth_tolerance_is_the_truncation() -> None:
    points = np.array([[0.0, 0.0, WALL_DEPTH + 0.05], [0.0, 0.0, WALL_DEPTH + 0.07]])
    seen = visible_vertices(points, _cameras(1), "eslam", CullOptions(truncation=0.06))
    np.testing.assert_array_equal(seen, [True, False])
    seen = visible_vertices(points, _cameras(1), "nice")
    np.testing.assert_array_equal(seen, [True, True])


def test_missing_depth_and_bad_inputs() -> None:
    poses = np.eye(4)[None]
    point = np.array([[0.0, 0.0, 1.0]])
    holes = CullCameras(poses, CAMERA, [np.zeros((CAMERA.height, CAMERA.width))])
    assert not visible_vertices(point, holes, "eslam")[0], "no depth, no observation"
    with pytest.raises(ConfigError, match="needs depth maps"):
        visible_vertices(point, CullCameras(poses, CAMERA), "eslam")
    with pytest.raises(ValueError, match="more depth maps than the 1 poses"):
        visible_vertices(point, CullCameras(poses, CAMERA, [holes.depths[0]] * 2), "eslam")
    with pytest.raises(ValueError, match="0 depth maps for 1 poses"):
        visible_vertices(point, CullCameras(poses, CAMERA, []), "eslam")
    with pytest.raises(ConfigError, match="unknown culling protocol"):
        visible_vertices(point, CullCameras(poses, CAMERA), "neural")


def test_subdivision_splits_long_edges_and_keeps_the_surface() -> None:
    mesh = _join(_wall(1.0), _box((0.0, 0.0, 0.0), 0.5, 50))
    mesh.colours[:4] = [[0, 0, 0], [100, 0, 0], [200, 0, 0], [100, 0, 0]]
    split = subdivide_long_edges(mesh, 0.3)
    corners = split.vertices[split.faces]
    edges = np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2)
    assert edges.max() <= 0.3 + 1e-12 and len(split.faces) > 16 * len(mesh.faces)

    def area(m: TriangleMesh) -> float:
        a, b, c = (m.vertices[m.faces[:, i]] for i in range(3))
        return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() / 2)

    assert area(split) == pytest.approx(area(mesh), rel=1e-12)
    np.testing.assert_array_equal(split.vertices[: len(mesh.vertices)], mesh.vertices)
    # new wall vertices lie on the wall, with colours interpolated along the edges
    wall = np.abs(split.vertices[:, 2] - WALL_DEPTH) < 1e-12
    centre = np.flatnonzero(wall & (np.abs(split.vertices[:, :2]).sum(1) < 1e-12))
    assert len(centre) == 1 and split.colours[centre[0], 0] == 100
    assert subdivide_long_edges(mesh, 10.0).faces.shape == mesh.faces.shape
