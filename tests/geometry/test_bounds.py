"""Scene bounds from depth: subsampled back-projection, robust boxes, coverage."""

from __future__ import annotations

import math

import pytest
import torch

from eslam.geometry.bounds import (
    bound_coverage,
    depth_points,
    estimate_bound,
    fraction_outside,
    robust_box,
    subsample_stride,
    union_box,
)
from eslam.geometry.pose import se3_exp
from eslam.types import Intrinsics

CAMERA = Intrinsics(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)


def test_subsample_stride_caps_the_point_count() -> None:
    assert subsample_stride(48, 64, 10_000) == 1
    for height, width, cap in ((480, 640, 10_000), (680, 1200, 10_000), (48, 64, 7)):
        stride = subsample_stride(height, width, cap)
        assert math.ceil(height / stride) * math.ceil(width / stride) <= cap
        if stride > 1:  # and the stride is the smallest that does
            assert math.ceil(height / (stride - 1)) * math.ceil(width / (stride - 1)) > cap


def test_depth_points_of_a_wall_seen_from_a_moved_camera() -> None:
    depth = torch.full((48, 64), 2.0, dtype=torch.float64)
    depth[:5] = 0.0  # invalid rows
    depth[10, :] = float("nan")
    depth[20, :] = 9.0  # beyond max_depth
    pose = se3_exp(torch.tensor([0.3, -0.2, 1.0, 0.0, 0.0, 0.4], dtype=torch.float64))
    points = depth_points(depth, CAMERA, pose, max_points=10_000, max_depth=5.0)
    assert len(points) == 64 * (48 - 5 - 2)
    # every point is 2 m in front of the camera along its optical axis
    camera_z = (points - pose[:3, 3]) @ pose[:3, :3]
    torch.testing.assert_close(camera_z[:, 2], torch.full_like(camera_z[:, 2], 2.0))
    assert len(depth_points(depth, CAMERA, pose, max_points=100)) <= 100
    assert len(depth_points(torch.zeros(48, 64), CAMERA, torch.eye(4))) == 0
    with pytest.raises(ValueError, match="depth must be"):
        depth_points(torch.ones(10, 10), CAMERA, torch.eye(4))


def test_estimate_bound_ignores_far_outliers_and_holds_the_camera() -> None:
    generator = torch.Generator().manual_seed(0)
    points = torch.rand(20_000, 3, generator=generator, dtype=torch.float64) * 2.0 + 1.0
    points[:40] = 50.0  # 0.2 % far outliers (depth spikes)
    centre = torch.tensor([0.0, 2.0, 2.0], dtype=torch.float64)
    bound = estimate_bound(points, margin=0.25, centres=centre)
    expected = torch.tensor([[-0.25, 3.25], [0.75, 3.25], [0.75, 3.25]], dtype=torch.float64)
    torch.testing.assert_close(bound, expected, rtol=0, atol=0.03)
    box = robust_box(points, percentile=0.0)
    assert float(box.max()) == 50.0
    with pytest.raises(ValueError, match="margin"):
        estimate_bound(points, margin=-1.0)
    with pytest.raises(ValueError, match="N >= 1"):
        robust_box(points[:0])


def test_coverage_reports_the_share_outside_and_the_box_needed() -> None:
    bound = torch.tensor([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]], dtype=torch.float64)
    grid = torch.linspace(0.05, 0.95, 10, dtype=torch.float64)
    inside = torch.cartesian_prod(grid, grid, grid)
    assert fraction_outside(inside, bound) == 0.0
    coverage = bound_coverage(inside, bound, margin=0.2)
    assert coverage.fraction_outside == 0.0 and not coverage.grows
    assert torch.equal(coverage.required, bound)
    shifted = inside + torch.tensor([0.5, 0.0, -0.3], dtype=torch.float64)
    coverage = bound_coverage(shifted, bound, margin=0.2)
    # x > 1 for x in {0.55..0.95}+0.5 -> 5 of 10 columns; z < 0 for 0.05, 0.15, 0.25 -> 3 of 10
    assert coverage.fraction_outside == pytest.approx(1.0 - 0.5 * 0.7)
    assert coverage.grows
    high_x = float(torch.quantile(shifted[:, 0], 0.995))
    low_z = float(torch.quantile(shifted[:, 2], 0.005))
    expected = torch.tensor([[0.0, high_x + 0.2], [0.0, 1.0], [low_z - 0.2, 1.0]])
    torch.testing.assert_close(coverage.required.float(), expected, rtol=0, atol=1e-6)
    assert fraction_outside(shifted, coverage.required) == 0.0
    empty = bound_coverage(inside[:0], bound, margin=0.2)
    assert empty.fraction_outside == 0.0 and not empty.grows
    a, b = bound, bound + 0.5
    torch.testing.assert_close(union_box(a, b), torch.tensor([[0.0, 1.5]] * 3).double())
