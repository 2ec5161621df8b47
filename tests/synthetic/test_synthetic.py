"""Synthetic scenes: exact depth, trajectory statistics, round trip through the Replica layout."""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree

from eslam.data.replica import REPLICA_DEPTH_SCALE, ReplicaSequence
from eslam.errors import InputError
from eslam.geometry.camera import backproject_depth, pixels_to_camera_directions, project_points
from eslam.synthetic import (
    SCENES,
    Scene,
    SynthConfig,
    build_scene,
    camera_trajectory,
    generate_sequence,
    render_frame,
    render_view,
    scene_mesh,
    synthetic_intrinsics,
    write_synthetic_sequence,
)
from eslam.synthetic.primitives import Cylinder, Sphere
from eslam.synthetic.render import cast_rays
from eslam.synthetic.scenes import describe_scene
from eslam.synthetic.sensor import KINECT_AXIAL_NOISE, sensor_depth
from eslam.synthetic.tessellation import MESH_TOLERANCE
from eslam.synthetic.trajectory import look_at
from eslam.types import Intrinsics

SMALL = SynthConfig(frames=4, width=80, height=60, seed=3)


def _steps(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame translation (m) and rotation angle (deg) between consecutive poses."""
    translation = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    relative = np.einsum("nji,njk->nik", poses[:-1, :3, :3], poses[1:, :3, :3])
    cosine = (np.trace(relative, axis1=1, axis2=2) - 1.0) / 2.0
    return translation, np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def _ray_mesh_depth(mesh, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Nearest t of origin + t d on a triangle mesh (Moller-Trumbore, a slow reference)."""
    tri = mesh.vertices[mesh.faces]
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    centre = tri.mean(axis=1)
    reach = np.linalg.norm(tri - centre[:, None], axis=2).max(axis=1) + 1e-6
    offset = centre - origin
    depths = []
    for d in directions:
        along = offset @ (d / np.linalg.norm(d))
        near = np.flatnonzero(np.einsum("fi,fi->f", offset, offset) - along**2 <= reach**2)
        p = np.cross(d, e2[near])
        det = np.einsum("fi,fi->f", e1[near], p)
        s = origin - v0[near]
        q = np.cross(s, e1[near])
        u = np.einsum("fi,fi->f", s, p) / det
        v = (q @ d) / det
        t = np.einsum("fi,fi->f", e2[near], q) / det
        hit = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9) & (t > 0)
        depths.append(t[hit].min() if hit.any() else np.inf)
    return np.array(depths)


def test_unknown_scene_lists_choices() -> None:
    with pytest.raises(ValueError, match="room"):
        SynthConfig(scene="castle")
    with pytest.raises(ValueError, match="choose one of: corridor, room"):
        build_scene("castle", 0)
    assert "room" in SCENES


def test_the_corridor_is_a_long_empty_box_the_camera_stays_inside() -> None:
    """Its views are planes only: no object, the camera box well inside, depth on every
    pixel (a closed box) and never nearer than its 0.8 m walls allow."""
    scene = build_scene("corridor", 2)
    (corridor,) = scene.primitives
    assert np.all(scene.camera_lo > corridor.lo + 0.7) and np.all(scene.camera_hi < corridor.hi)
    length, width = corridor.hi[:2] - corridor.lo[:2]
    assert length > 3.5 * width
    assert json.dumps(describe_scene(scene))
    config = SynthConfig(frames=5, width=40, height=30, seed=2, scene="corridor")
    for frame in generate_sequence(config):
        position = frame.pose_gt[:3, 3]
        assert np.all(position >= scene.camera_lo) and np.all(position <= scene.camera_hi)
        assert frame.depth.min() > 0.5


def test_bad_config_values_raise() -> None:
    for bad in ({"frames": 0}, {"width": 1}, {"hfov_deg": 180.0}, {"step_translation": 0.0}):
        with pytest.raises(ValueError):
            SynthConfig(**bad)


def test_same_seed_same_sequence_other_seed_other_scene() -> None:
    first, second = list(generate_sequence(SMALL)), list(generate_sequence(SMALL))
    other = list(generate_sequence(replace(SMALL, seed=4)))
    for a, b, c in zip(first, second, other, strict=True):
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.pose_gt, b.pose_gt)
        assert not np.array_equal(a.depth, c.depth)
    assert describe_scene(build_scene("room", 3)) == describe_scene(build_scene("room", 3))
    assert describe_scene(build_scene("room", 3)) != describe_scene(build_scene("room", 4))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_trajectory_is_smooth_hand_held_and_inside_the_free_area(seed: int) -> None:
    config = SynthConfig(frames=300, seed=seed)
    scene = build_scene("room", seed)
    poses = camera_trajectory(scene, config)
    assert poses.shape == (300, 4, 4) and poses.dtype == np.float64
    rotations = poses[:, :3, :3]
    np.testing.assert_allclose(
        np.einsum("nji,njk->nik", rotations, rotations), np.eye(3)[None].repeat(300, 0), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(rotations), 1.0, atol=1e-12)
    np.testing.assert_array_equal(poses[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (300, 1)))
    for window in (poses[:60], poses):
        translation, rotation = _steps(window)
        assert 0.005 <= np.median(translation) <= 0.02 and translation.max() < 0.03
        assert 0.2 <= np.median(rotation) <= 1.0 and rotation.max() < 2.0
    positions = poses[:, :3, 3]
    assert np.all(positions >= scene.camera_lo - 1e-9) and np.all(
        positions <= scene.camera_hi + 1e-9
    )
    assert 1.2 <= positions[:, 2].min() and positions[:, 2].max() <= 1.8
    centre_depth = [cast_rays(scene, p[:3, 3], p[None, :3, 2])[0][0] for p in poses]
    assert min(centre_depth) > 0.5
    # frame i does not depend on the number of frames
    np.testing.assert_array_equal(camera_trajectory(scene, replace(config, frames=20)), poses[:20])


@pytest.mark.parametrize("step_deg", [3.0, 6.0, 10.0])
def test_a_fast_yaw_stays_a_yaw(step_deg: float) -> None:
    """Tens to hundreds of degrees per second of yaw: the pitch and roll swings stay
    bounded, so the camera never looks straight down, where the look-at turns the image
    over (at 6 degrees per frame the unbounded swings once made a 175-degree step)."""
    config = SynthConfig(frames=300, seed=0, step_rotation_deg=step_deg)
    poses = camera_trajectory(build_scene("room", 0), config)
    _, rotation = _steps(poses)
    assert rotation.max() < 1.6 * step_deg  # the yaw step (+-30 %) and a little sway
    forward = poses[:, :3, 2]  # the optical axis in the world (z up)
    pitch = np.degrees(np.arcsin(forward[:, 2]))
    assert pitch.min() > -50.0 and pitch.max() < 15.0


def test_look_at_builds_opencv_axes_and_survives_looking_straight_down() -> None:
    pose = look_at(np.zeros(3), np.array([1.0, 0.0, 0.0]))
    np.testing.assert_allclose(pose[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)
    down = look_at(np.array([0.0, 0.0, 1.5]), np.array([0.0, 0.0, 0.0]))
    assert np.all(np.isfinite(down))
    np.testing.assert_allclose(down[:3, :3].T @ down[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(down[:3, 2], [0.0, 0.0, -1.0])


def test_depth_equals_known_geometry() -> None:
    room = build_scene("room", 0).primitives[0]
    empty = Scene((room,), np.zeros(3), np.zeros(3))
    intrinsics = Intrinsics(65, 49, 100.0, 100.0, 32.0, 24.0)
    height = 1.37
    _, depth = render_frame(
        empty, intrinsics, look_at(np.array([0.1, -0.2, height]), [0.1, -0.2, 0.0])
    )
    np.testing.assert_allclose(depth, height, rtol=1e-6)  # the floor, seen straight down
    eye = np.array([0.0, 0.0, 1.2])
    _, depth = render_frame(empty, intrinsics, look_at(eye, np.array([1.0, 0.0, 1.2])))
    np.testing.assert_allclose(depth, room.hi[0], rtol=1e-6)  # a wall, seen square on
    sphere = Sphere(np.array([1.0, 0.5, 1.2]), 0.3, room.materials[0])
    _, depth = render_frame(
        Scene((room, sphere), np.zeros(3), np.zeros(3)), intrinsics, look_at(eye, sphere.centre)
    )
    expected = np.linalg.norm(sphere.centre - eye) - sphere.radius
    assert depth[24, 32] == pytest.approx(expected, abs=1e-6)  # the exact centre pixel


def test_depth_agrees_with_ray_casting_the_ground_truth_mesh() -> None:
    config = SynthConfig(frames=40, width=160, height=120, seed=0)
    scene = build_scene("room", 0)
    mesh = scene_mesh(scene)
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    assert mesh.colours.dtype == np.uint8 and mesh.colours.shape == mesh.vertices.shape
    intrinsics = synthetic_intrinsics(config)
    rng = np.random.default_rng(0)
    for pose in camera_trajectory(scene, config)[[0, 39]]:
        view = render_view(scene, intrinsics, pose)
        # away from silhouettes: a chord 0.2 mm inside the surface is < 0.4 mm along the ray
        usable = view.cos_incidence > 0.5
        curved = np.isin(
            view.primitive,
            [i for i, p in enumerate(scene.primitives) if isinstance(p, (Sphere, Cylinder))],
        )
        rows, cols = [], []
        for mask in (usable & curved, usable & ~curved):
            r, c = np.nonzero(mask)
            pick = rng.choice(len(r), min(len(r), 100), replace=False)
            rows.append(r[pick])
            cols.append(c[pick])
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        assert len(rows) > 150
        uv = torch.tensor(np.stack([cols, rows], 1), dtype=torch.float64)
        world = pixels_to_camera_directions(uv, intrinsics).numpy() @ pose[:3, :3].T
        mesh_depth = _ray_mesh_depth(mesh, pose[:3, 3], world)
        error = np.abs(mesh_depth - view.depth[rows, cols])
        assert error.max() < 1e-3, error.max()
        assert np.median(error) < 1e-4


def test_curved_surfaces_are_tessellated_within_the_tolerance() -> None:
    for primitive in build_scene("room", 1).primitives:
        surface = primitive.surface()
        tri = surface.vertices[surface.faces]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        # every triangle faces the side the camera sees
        assert np.all(np.einsum("fi,fi->f", normal, surface.normals[surface.faces].sum(1)) > 0)
        centroids = tri.mean(axis=1)
        if isinstance(primitive, Sphere):
            gap = primitive.radius - np.linalg.norm(centroids - primitive.centre, axis=1)
            assert 0 <= gap.min() and gap.max() < MESH_TOLERANCE
        if isinstance(primitive, Cylinder):
            side = surface.parts[surface.faces[:, 0]] == 0
            radial = np.linalg.norm(centroids[side, :2] - primitive.centre, axis=1)
            assert (primitive.radius - radial).max() < MESH_TOLERANCE


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    config = SynthConfig(frames=60, width=320, height=240, seed=0)
    root = write_synthetic_sequence(tmp_path_factory.mktemp("synth") / "seq", config)
    return root, list(generate_sequence(config))


def test_written_sequence_reads_back_with_depth_and_poses_to_1mm(written) -> None:
    root, frames = written
    sequence = ReplicaSequence(root)
    assert len(sequence) == 60
    assert sequence.intrinsics == frames[0].intrinsics
    for original in frames:
        frame = sequence[original.index]
        valid = original.depth > 0
        assert valid.all()  # a closed room: every pixel hits something
        error = np.abs(frame.depth - original.depth)[valid]
        assert error.max() <= 0.5 / REPLICA_DEPTH_SCALE + 1e-6
        assert 0.5 < original.depth.min() and original.depth.max() < 5.0
        np.testing.assert_allclose(frame.pose_gt, original.pose_gt, rtol=0, atol=1e-9)
        assert np.abs(frame.rgb.astype(float) - original.rgb).mean() < 4.0  # JPEG
    info = json.loads((root / "synth.json").read_text())
    assert info["config"]["frames"] == 60 and info["scene"][0]["type"] == "RoomBox"
    mesh = trimesh.load(root / "mesh.ply", process=False)
    np.testing.assert_allclose(
        mesh.vertices, scene_mesh(build_scene("room", 0)).vertices, atol=1e-6
    )
    with pytest.raises(InputError, match="not empty"):
        write_synthetic_sequence(root, SynthConfig(frames=1, width=8, height=6))


def test_two_frames_back_project_onto_the_same_surfaces(written) -> None:
    root, _ = written
    sequence = ReplicaSequence(root)
    a, b = sequence[0], sequence[45]
    points_a = backproject_depth(
        torch.from_numpy(a.depth).double(), a.intrinsics, torch.from_numpy(a.pose_gt)
    )
    points_b = backproject_depth(
        torch.from_numpy(b.depth).double(), b.intrinsics, torch.from_numpy(b.pose_gt)
    )
    points_a = points_a.reshape(-1, 3)
    uv, z = project_points(points_a, b.intrinsics, torch.from_numpy(b.pose_gt))
    inside = (z > 0) & (uv[:, 0] > 0) & (uv[:, 0] < 319) & (uv[:, 1] > 0) & (uv[:, 1] < 239)
    assert inside.float().mean() > 0.5  # the frames overlap
    distance, _ = cKDTree(points_b.reshape(-1, 3).numpy()).query(points_a[inside].numpy())
    assert np.median(distance) < 0.01
    # the mesh passes through the back-projected points too
    mesh = scene_mesh(build_scene("room", 0))
    vertex_distance, _ = cKDTree(mesh.vertices).query(points_a[::97].numpy())
    assert np.median(vertex_distance) < 0.05  # vertices are a 5 cm grid


def test_colour_carries_information(written) -> None:
    _, frames = written
    scene = build_scene("room", 0)
    sums: dict[int, np.ndarray] = {}
    counts: dict[int, int] = {}
    for frame in frames[::10]:
        rgb = frame.rgb.reshape(-1, 3)
        assert rgb.astype(float).std(axis=0).mean() > 20
        assert len(np.unique(rgb, axis=0)) > 2000
        view = render_view(scene, frame.intrinsics, frame.pose_gt)
        owner = view.primitive.reshape(-1)
        for index in np.unique(owner):
            sums[index] = sums.get(index, 0) + rgb[owner == index].sum(axis=0)
            counts[index] = counts.get(index, 0) + int((owner == index).sum())
    means = np.array([sums[i] / counts[i] for i in sums if counts[i] > 500])
    assert len(means) >= 3
    gaps = np.linalg.norm(means[:, None] - means[None], axis=-1)[np.triu_indices(len(means), 1)]
    assert gaps.min() > 10.0, gaps.min()


def test_sensor_effects_are_off_by_default_and_behave_as_stated() -> None:
    config = SynthConfig(frames=1, width=160, height=120, seed=2)
    scene = build_scene("room", 2)
    view = render_view(scene, synthetic_intrinsics(config), camera_trajectory(scene, config)[0])
    np.testing.assert_array_equal(next(generate_sequence(config)).depth, view.depth)
    noisy = next(generate_sequence(replace(config, depth_noise=True))).depth
    np.testing.assert_array_equal(
        noisy, next(generate_sequence(replace(config, depth_noise=True))).depth
    )
    error = noisy.astype(np.float64) - view.depth
    a, b, z0 = KINECT_AXIAL_NOISE
    spread = []
    for near, far in ((1.0, 2.0), (2.5, 4.0)):
        band = (view.depth >= near) & (view.depth < far)
        assert band.sum() > 1000
        expected = np.sqrt(np.mean((a + b * (view.depth[band].astype(np.float64) - z0) ** 2) ** 2))
        assert error[band].std() == pytest.approx(expected, rel=0.15)
        spread.append(error[band].std())
    assert spread[1] > 1.5 * spread[0]  # noise grows with depth
    holes = next(generate_sequence(replace(config, missing_depth=True))).depth
    missing = holes == 0
    assert 0.01 < missing.mean() < 0.2
    np.testing.assert_array_equal(holes[~missing], view.depth[~missing])
    rng = np.random.default_rng(0)
    both = sensor_depth(view, rng, replace(config, depth_noise=True, missing_depth=True))
    assert both.dtype == np.float32 and (both == 0).mean() > 0.01


def test_render_640x480_is_fast() -> None:
    config = SynthConfig(frames=1)
    scene = build_scene("room", 0)
    pose = camera_trajectory(scene, config)[0]
    intrinsics = synthetic_intrinsics(config)
    render_frame(scene, intrinsics, pose)
    start = time.perf_counter()
    rgb, depth = render_frame(scene, intrinsics, pose)
    elapsed = time.perf_counter() - start
    print(f"640x480 render: {elapsed * 1000:.0f} ms")
    assert rgb.shape == (480, 640, 3) and depth.shape == (480, 640)
    assert elapsed < 2.0
    assert math.isfinite(float(depth.max()))
