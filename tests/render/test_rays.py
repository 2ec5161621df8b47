"""Pixel sampling and world rays from pixels (differentiable w.r.t. the pose)."""

from __future__ import annotations

import pytest
import torch

from eslam.geometry.camera import backproject_depth, pixels_to_camera_directions
from eslam.geometry.rotation import quaternion_to_matrix
from eslam.render.rays import camera_directions, rays_from_pixels, sample_pixels
from eslam.types import Intrinsics

K = Intrinsics(width=7, height=5, fx=4.0, fy=3.0, cx=3.2, cy=1.9)


def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def pose(seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(4, generator=g, dtype=torch.float64)
    c2w = torch.eye(4, dtype=torch.float64)
    c2w[:3, :3] = quaternion_to_matrix(q / q.norm())
    c2w[:3, 3] = torch.randn(3, generator=g, dtype=torch.float64)
    return c2w


def test_sample_pixels_respects_border_and_validity() -> None:
    valid = torch.ones(6, 8, dtype=torch.bool)
    pixels = sample_pixels(valid, 2000, border=2, generator=gen())
    assert pixels.shape == (2000,) and pixels.dtype == torch.int64
    rows, cols = pixels // 8, pixels % 8
    assert torch.all((rows >= 2) & (rows < 4) & (cols >= 2) & (cols < 6))
    assert len(torch.unique(pixels)) == 8  # every one of the 2 x 4 inner pixels is drawn


def test_sample_pixels_with_one_valid_pixel_inside_the_border() -> None:
    valid = torch.zeros(6, 8, dtype=torch.bool)
    valid[0, :] = True  # valid but inside the border
    valid[3, 4] = True
    pixels = sample_pixels(valid, 50, border=1, generator=gen())
    assert torch.all(pixels == 3 * 8 + 4)


def test_sample_pixels_is_roughly_uniform_and_seeded() -> None:
    valid = torch.zeros(4, 4, dtype=torch.bool)
    valid[1, 1] = valid[2, 2] = True
    pixels = sample_pixels(valid, 4000, border=0, generator=gen(5))
    share = (pixels == 5).float().mean()
    assert 0.45 < share < 0.55
    assert torch.equal(pixels, sample_pixels(valid, 4000, border=0, generator=gen(5)))


def test_sample_pixels_errors() -> None:
    valid = torch.ones(6, 8, dtype=torch.bool)
    with pytest.raises(ValueError, match="no valid pixel at least 3 px"):
        sample_pixels(valid, 10, border=3)
    with pytest.raises(ValueError, match="no valid pixel"):
        sample_pixels(torch.zeros(6, 8, dtype=torch.bool), 10, border=0)
    with pytest.raises(ValueError, match="bool"):
        sample_pixels(valid.float(), 10, border=0)


def test_camera_directions_are_row_major_unit_z() -> None:
    directions = camera_directions(K, dtype=torch.float64)
    assert directions.shape == (35, 3)
    u, v = 4, 3
    expected = pixels_to_camera_directions(torch.tensor([u, v], dtype=torch.float64), K)
    torch.testing.assert_close(directions[v * K.width + u], expected)
    assert torch.all(directions[:, 2] == 1.0)


def test_rays_from_pixels_identity_pose() -> None:
    directions = camera_directions(K)
    depth, rgb = torch.ones(35), torch.rand(35, 3, generator=gen())
    rays = rays_from_pixels(directions, torch.eye(4), depth, rgb)
    assert torch.all(rays.origins == 0)
    torch.testing.assert_close(rays.directions, directions)
    assert rays.depth is depth and rays.rgb is rgb and len(rays) == 35


def test_point_at_depth_matches_backprojection() -> None:
    c2w = pose(1)
    depth_map = 0.5 + torch.rand(K.height, K.width, generator=gen(2), dtype=torch.float64)
    directions = camera_directions(K, dtype=torch.float64)
    pixels = torch.tensor([0, 9, 17, 34])
    depth = depth_map.reshape(-1)[pixels]
    rays = rays_from_pixels(directions[pixels], c2w, depth, torch.zeros(4, 3))
    points = rays.origins + depth[:, None] * rays.directions
    expected = backproject_depth(depth_map, K, c2w).reshape(-1, 3)[pixels]
    torch.testing.assert_close(points, expected)
    # One pose per ray gives the same rays.
    batched = rays_from_pixels(directions[pixels], c2w.expand(4, 4, 4), depth, torch.zeros(4, 3))
    torch.testing.assert_close(batched.directions, rays.directions)
    torch.testing.assert_close(batched.origins, rays.origins)


def test_gradient_flows_to_the_pose() -> None:
    c2w = pose(3).requires_grad_(True)
    directions = camera_directions(K, dtype=torch.float64)
    rays = rays_from_pixels(directions, c2w, torch.ones(35), torch.zeros(35, 3))
    points = rays.origins + rays.directions
    points.square().sum().backward()
    assert c2w.grad is not None
    assert torch.all(c2w.grad[:3, :3] != 0) and torch.all(c2w.grad[:3, 3] != 0)


def test_rays_from_pixels_checks_shapes() -> None:
    directions = camera_directions(K)
    with pytest.raises(ValueError, match="c2w"):
        rays_from_pixels(directions, torch.eye(3), torch.ones(35), torch.zeros(35, 3))
    with pytest.raises(ValueError, match="depth"):
        rays_from_pixels(directions, torch.eye(4), torch.ones(34), torch.zeros(35, 3))
