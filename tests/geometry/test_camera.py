"""Pinhole camera maths and Intrinsics resizing/cropping, on hand values and round trips."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from eslam.geometry import (
    backproject_depth,
    camera_to_world_rays,
    pixel_grid,
    pixels_to_camera_directions,
    project_points,
)
from eslam.types import Intrinsics

VGA = Intrinsics(width=640, height=480, fx=500.0, fy=510.0, cx=319.5, cy=239.5)
ODD = Intrinsics(width=7, height=5, fx=4.0, fy=3.0, cx=3.2, cy=1.9)


def random_pose(seed: int) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    pose = np.eye(4)
    pose[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    pose[:3, 3] = rng.normal(size=3)
    return torch.as_tensor(pose)


def test_scaled_hand_values() -> None:
    half = VGA.scaled(320, 240)
    assert (half.width, half.height) == (320, 240)
    assert (half.fx, half.fy, half.cx, half.cy) == (250.0, 255.0, 159.5, 119.5)
    # A principal point off the centre: cx' = (cx + 0.5) * s - 0.5.
    off = Intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0).scaled(320, 240)
    assert (off.cx, off.cy) == (159.75, 119.75)
    double = VGA.scaled(1280, 960)
    assert (double.fx, double.cx, double.cy) == (1000.0, 639.5, 479.5)
    assert VGA.scaled(640, 480) == VGA


def test_cropped_hand_values() -> None:
    cropped = VGA.cropped(10, 20, 5, 7)
    assert (cropped.width, cropped.height) == (625, 453)
    assert (cropped.fx, cropped.fy, cropped.cx, cropped.cy) == (500.0, 510.0, 309.5, 219.5)


def test_scaling_then_projecting_gives_the_scaled_pixel() -> None:
    rng = np.random.default_rng(0)
    points = torch.as_tensor(rng.uniform([-1, -1, 1], [1, 1, 5], size=(50, 3)))
    eye = torch.eye(4, dtype=torch.float64)
    uv, _ = project_points(points, VGA, eye)
    for width, height in [(320, 240), (1280, 960), (200, 150), (641, 479)]:
        sx, sy = width / VGA.width, height / VGA.height
        uv_scaled, _ = project_points(points, VGA.scaled(width, height), eye)
        expected = torch.stack(((uv[:, 0] + 0.5) * sx - 0.5, (uv[:, 1] + 0.5) * sy - 0.5), -1)
        torch.testing.assert_close(uv_scaled, expected, rtol=0, atol=1e-9)
    # The image-plane extent maps to the new extent: pixel edges -0.5 and W - 0.5.
    small = VGA.scaled(320, 240)
    corner = pixels_to_camera_directions(torch.tensor([[-0.5, -0.5]], dtype=torch.float64), VGA)
    uv_corner, _ = project_points(corner, small, eye)
    torch.testing.assert_close(uv_corner, torch.tensor([[-0.5, -0.5]], dtype=torch.float64))


def test_cropping_then_projecting_shifts_the_pixel() -> None:
    rng = np.random.default_rng(1)
    points = torch.as_tensor(rng.uniform([-1, -1, 1], [1, 1, 5], size=(50, 3)))
    eye = torch.eye(4, dtype=torch.float64)
    uv, _ = project_points(points, VGA, eye)
    uv_cropped, _ = project_points(points, VGA.cropped(10, 20, 5, 7), eye)
    shift = torch.tensor([10.0, 20.0], dtype=torch.float64)
    torch.testing.assert_close(uv_cropped, uv - shift, rtol=0, atol=1e-12)


def test_pixel_grid() -> None:
    grid = pixel_grid(ODD, dtype=torch.float64)
    assert grid.shape == (5, 7, 2) and grid.dtype == torch.float64
    assert grid[0, 0].tolist() == [0.0, 0.0]
    assert grid[2, 4].tolist() == [4.0, 2.0]  # uv[v, u] = (u, v)
    assert grid[-1, -1].tolist() == [6.0, 4.0]
    assert pixel_grid(ODD).dtype == torch.float32


def test_directions_hand_values() -> None:
    uv = torch.tensor([[3.2, 1.9], [7.2, 4.9]], dtype=torch.float64)
    directions = pixels_to_camera_directions(uv, ODD)
    torch.testing.assert_close(
        directions, torch.tensor([[0.0, 0.0, 1.0], [1.0, 1.0, 1.0]], dtype=torch.float64)
    )


def test_pixel_ray_point_round_trip() -> None:
    rng = np.random.default_rng(2)
    uv = torch.as_tensor(rng.uniform([0, 0], [639, 479], size=(200, 2)))
    depth = torch.as_tensor(rng.uniform(0.1, 10.0, size=200))
    pose = random_pose(3)
    origins, directions = camera_to_world_rays(pixels_to_camera_directions(uv, VGA), pose)
    torch.testing.assert_close(origins, pose[:3, 3].expand(200, 3), rtol=0, atol=0)
    points = origins + directions * depth[:, None]
    uv_back, z = project_points(points, VGA, pose)
    torch.testing.assert_close(uv_back, uv, rtol=0, atol=1e-9)
    torch.testing.assert_close(z, depth, rtol=0, atol=1e-9)


def test_rays_with_one_pose_per_direction() -> None:
    poses = torch.stack([random_pose(s) for s in range(4)])
    directions = torch.tensor([[0.1, -0.2, 1.0]], dtype=torch.float64).expand(4, 3)
    origins, world = camera_to_world_rays(directions, poses)
    assert origins.shape == world.shape == (4, 3)
    for i in range(4):
        torch.testing.assert_close(world[i], poses[i, :3, :3] @ directions[i])
        torch.testing.assert_close(origins[i], poses[i, :3, 3])


@pytest.mark.parametrize("with_pose", [False, True])
def test_backproject_depth_projects_back_to_its_pixels(with_pose: bool) -> None:
    rng = np.random.default_rng(4)
    depth = torch.as_tensor(rng.uniform(0.5, 4.0, size=(5, 7)))
    pose = random_pose(5) if with_pose else torch.eye(4, dtype=torch.float64)
    points = backproject_depth(depth, ODD, pose if with_pose else None)
    assert points.shape == (5, 7, 3)
    uv, z = project_points(points.reshape(-1, 3), ODD, pose)
    torch.testing.assert_close(uv, pixel_grid(ODD, torch.float64).reshape(-1, 2), rtol=0, atol=1e-9)
    torch.testing.assert_close(z, depth.reshape(-1), rtol=0, atol=1e-9)
    if not with_pose:
        torch.testing.assert_close(points[..., 2], depth, rtol=0, atol=0)
    # Batched (..., 3) input to project_points gives the same answer.
    uv_batched, z_batched = project_points(points, ODD, pose)
    assert uv_batched.shape == (5, 7, 2) and z_batched.shape == (5, 7)
    torch.testing.assert_close(uv_batched.reshape(-1, 2), uv, rtol=0, atol=0)


def test_backproject_matches_rays() -> None:
    depth = torch.full((5, 7), 2.0, dtype=torch.float64)
    pose = random_pose(6)
    points = backproject_depth(depth, ODD, pose)
    dirs = pixels_to_camera_directions(pixel_grid(ODD, torch.float64), ODD)
    origins, directions = camera_to_world_rays(dirs, pose)
    torch.testing.assert_close(points, origins + 2.0 * directions, rtol=0, atol=1e-12)


def test_projection_matches_calibration_matrix() -> None:
    rng = np.random.default_rng(7)
    points_cam = rng.uniform([-1, -1, 0.5], [1, 1, 3], size=(30, 3))
    homogeneous = points_cam @ VGA.matrix().T
    expected = homogeneous[:, :2] / homogeneous[:, 2:]
    uv, z = project_points(torch.as_tensor(points_cam), VGA, torch.eye(4, dtype=torch.float64))
    np.testing.assert_allclose(uv.numpy(), expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(z.numpy(), points_cam[:, 2], rtol=0, atol=0)


def test_points_behind_the_camera_have_negative_z() -> None:
    pose = random_pose(8)
    forward = pose[:3, 2]
    centre = pose[:3, 3]
    points = torch.stack((centre + 2.0 * forward, centre - 2.0 * forward, centre - 1e-14 * forward))
    _, z = project_points(points, VGA, pose)
    assert z[0].item() == pytest.approx(2.0) and z[1].item() == pytest.approx(-2.0)
    assert z[2].item() < 0
    uv, _ = project_points(points, VGA, pose)
    assert torch.isfinite(uv).all()


def test_float32_and_gradients() -> None:
    depth = torch.full((5, 7), 1.5, requires_grad=True)
    points = backproject_depth(depth, ODD, torch.eye(4))
    assert points.dtype == torch.float32
    uv, z = project_points(points.reshape(-1, 3), ODD, torch.eye(4))
    (uv.sum() + z.sum()).backward()
    assert depth.grad is not None and torch.isfinite(depth.grad).all()
    torch.testing.assert_close(uv, pixel_grid(ODD).reshape(-1, 2), rtol=0, atol=1e-5)
