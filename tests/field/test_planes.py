"""Feature planes: bound fitting, normalisation, grid sizes, fast == reference sampling."""

from __future__ import annotations

import pytest
import torch

from eslam.field.plane_sampling import padding_mask, sample_planes_fast, sample_planes_reference
from eslam.field.planes import (
    PlaneLevel,
    PlaneSet,
    fit_bound,
    grid_size,
    normalize_points,
    plane_shapes,
)

ODD_GRIDS = [(7, 5, 3), (3, 7, 5), (5, 3, 7), (2, 2, 9), (1, 4, 6), (6, 6, 6)]


def _points(count: int, seed: int = 0, dtype=torch.float32) -> torch.Tensor:
    """Random normalised points in [-1.5, 1.5]^3 plus points exactly on the border."""
    generator = torch.Generator().manual_seed(seed)
    inside = torch.rand(count, 3, generator=generator, dtype=dtype) * 3.0 - 1.5
    border = torch.tensor(
        [[-1, -1, -1], [1, 1, 1], [1, -1, 0.3], [-1, 0.2, 1], [0.5, 1, -1], [1, 1.2, -1.3]],
        dtype=dtype,
    )
    return torch.cat((inside, border))


def _level(grid, channels=4, seed=0, sampling="fast", std=0.1) -> PlaneLevel:
    """Planes with features of a trained map's scale (float32 bilinear interpolation
    rounds to ~1e-6 of the feature magnitude, in either path)."""
    torch.manual_seed(seed)
    return PlaneLevel(grid, channels, init_std=std, sampling=sampling)


def test_fit_bound_hand_values():
    bound = torch.tensor([[0.0, 1.0], [0.0, 0.5], [-1.0, 1.0]])
    fitted = fit_bound(bound, 0.24)
    expected = torch.tensor([[0.0, 1.2], [0.0, 0.72], [-1.0, 1.16]])
    assert fitted.dtype == torch.float32
    torch.testing.assert_close(fitted, expected, rtol=0, atol=1e-6)


def test_fit_bound_keeps_exact_multiples_and_is_idempotent():
    bound = torch.tensor([[0.0, 4.8], [1.0, 3.4], [-2.4, 0.0]])
    fitted = fit_bound(bound, 0.24)
    torch.testing.assert_close(fitted, bound, rtol=0, atol=1e-6)
    odd = torch.tensor([[-1.9, 7.9], [-2.2, 4.5], [-2.5, 2.3]])
    once = fit_bound(odd, 0.24)
    torch.testing.assert_close(fit_bound(once, 0.24), once, rtol=0, atol=1e-6)
    assert fit_bound(odd.double(), 0.24).dtype == torch.float64


@pytest.mark.parametrize(
    "bad", [torch.zeros(2, 2), torch.tensor([[0.0, 1.0], [1.0, 1.0], [0.0, 1.0]])]
)
def test_fit_bound_rejects_bad_bounds(bad):
    with pytest.raises(ValueError, match="bound"):
        fit_bound(bad, 0.24)


def test_normalize_points_corners_and_centre():
    bound = torch.tensor([[0.0, 1.2], [0.0, 0.72], [-1.0, 1.16]])
    points = torch.tensor([[0.0, 0.0, -1.0], [1.2, 0.72, 1.16], [0.6, 0.36, 0.08], [2.4, 0, -1]])
    expected = torch.tensor([[-1.0, -1, -1], [1, 1, 1], [0, 0, 0], [3, -1, -1]])
    torch.testing.assert_close(normalize_points(points, bound), expected, rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        normalize_points(torch.zeros(4, 2), bound)


def test_grid_size_and_plane_shapes():
    bound = torch.tensor([[0.0, 4.8], [0.0, 2.4], [-1.2, 1.2]])
    assert grid_size(bound, 0.24) == (20, 10, 10)
    assert grid_size(bound, 0.06) == (80, 40, 40)
    assert grid_size(bound, 0.03) == (160, 80, 80)
    assert grid_size(bound, 5.0) == (2, 2, 2)
    assert plane_shapes((7, 5, 3)) == ((5, 7), (3, 7), (3, 5))


def test_plane_level_layout_and_init():
    level = _level((7, 5, 3), channels=6)
    assert level.planes.shape == (3, 6, 5, 7)
    assert level.shapes == ((5, 7), (3, 7), (3, 5))
    padding = padding_mask(level.shapes, 5, 7)
    assert level.planes.detach()[padding.expand_as(level.planes)].abs().max() == 0
    assert level.numel_used() == 6 * (5 * 7 + 3 * 7 + 3 * 5)
    torch.manual_seed(0)
    big = PlaneLevel((40, 30, 20), 8, init_std=0.01)
    used = big.planes.detach()[~big.padding.expand_as(big.planes)]
    assert used.numel() == big.numel_used()
    assert abs(used.std().item() - 0.01) < 5e-4 and abs(used.mean().item()) < 5e-4


@pytest.mark.parametrize("grid", ODD_GRIDS)
def test_fast_equals_reference_values_and_gradients(grid):
    level = _level(grid)
    points = _points(300, seed=sum(grid))
    results = []
    for sample in (sample_planes_reference, sample_planes_fast):
        planes = level.planes.detach().clone().requires_grad_(True)
        pts = points.clone().requires_grad_(True)
        if sample is sample_planes_fast:
            out = sample(planes, level.shapes, pts, level.padding)
        else:
            out = sample(planes, level.shapes, pts)
        weights = torch.randn(out.shape, generator=torch.Generator().manual_seed(1))
        (out * weights).sum().backward()
        results.append((out.detach(), planes.grad, pts.grad))
    (ref, ref_gp, ref_gx), (fast, fast_gp, fast_gx) = results
    assert ref.shape == (len(points), level.channels)
    torch.testing.assert_close(fast, ref, rtol=0, atol=1e-6)
    # A plane entry's gradient sums over many points (here up to ~5 in size), summed in
    # a different order by the two paths: compare relative to the largest entry.
    torch.testing.assert_close(fast_gp, ref_gp, rtol=0, atol=1e-6 * ref_gp.abs().max().item())
    torch.testing.assert_close(fast_gx, ref_gx, rtol=0, atol=1e-6)


def test_fast_is_as_accurate_as_reference_on_a_large_grid():
    """Unit-scale features on a Replica-size grid: both float32 paths against float64."""
    level = _level((232, 160, 120), std=1.0)
    points = _points(5000)
    truth = sample_planes_reference(level.planes.double(), level.shapes, points.double())
    with torch.no_grad():
        ref = sample_planes_reference(level.planes, level.shapes, points)
        fast = level.sample(points)
    ref_error = (ref.double() - truth).abs().max().item()
    fast_error = (fast.double() - truth).abs().max().item()
    assert ref_error < 2e-4
    assert fast_error < 2 * ref_error


@pytest.mark.parametrize("sampling", ["fast", "fused"])
@pytest.mark.parametrize("grid", ODD_GRIDS)
def test_fast_and_fused_equal_reference_in_float64(grid, sampling):
    level = _level(grid, std=1.0, sampling=sampling).double()
    points = _points(200, dtype=torch.float64)
    grads = []
    for path in ("reference", sampling):
        level.sampling = path
        level.planes.grad = None
        pts = points.clone().requires_grad_(True)
        out = level.sample(pts)
        assert out.dtype == torch.float64
        (out * torch.linspace(-1, 1, out.numel()).view_as(out)).sum().backward()
        grads.append((out.detach(), level.planes.grad.clone(), pts.grad))
    for ref, fast in zip(*grads, strict=True):
        torch.testing.assert_close(fast, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("sampling", ["reference", "fast", "fused"])
def test_padding_gets_exactly_zero_gradient(sampling):
    level = _level((7, 5, 3), sampling=sampling)
    level.sample(_points(500)).square().sum().backward()
    grad = level.planes.grad
    padding = level.padding.expand_as(grad)
    assert grad[padding].abs().max() == 0
    assert (grad[~padding] != 0).float().mean() > 0.9


@pytest.mark.parametrize("sampling", ["reference", "fast", "fused"])
def test_grid_vertex_returns_vertex_feature_sum(sampling):
    nx, ny, nz = 7, 5, 3
    level = _level((nx, ny, nz), sampling=sampling)
    i, j, k = 4, 1, 2
    point = torch.tensor([[-1 + 2 * i / (nx - 1), -1 + 2 * j / (ny - 1), -1 + 2 * k / (nz - 1)]])
    planes = level.planes.detach()
    expected = planes[0, :, j, i] + planes[1, :, k, i] + planes[2, :, k, j]
    torch.testing.assert_close(level.sample(point)[0].detach(), expected, rtol=0, atol=1e-6)


def test_bilinear_midpoint_and_border_padding():
    nx, ny, nz = 7, 5, 3
    level = _level((nx, ny, nz))
    planes = level.planes.detach()
    # Halfway between x vertices 2 and 3 on the vertex row y = 0, z = 0.
    point = torch.tensor([[-1 + 5 / (nx - 1), -1.0, -1.0]])
    expected = (
        0.5 * (planes[0, :, 0, 2] + planes[0, :, 0, 3])
        + 0.5 * (planes[1, :, 0, 2] + planes[1, :, 0, 3])
        + planes[2, :, 0, 0]
    )
    torch.testing.assert_close(level.sample(point)[0].detach(), expected, rtol=0, atol=1e-6)
    outside = torch.tensor([[3.0, -7.0, 0.25]])
    clamped = torch.tensor([[1.0, -1.0, 0.25]])
    torch.testing.assert_close(level.sample(outside), level.sample(clamped), rtol=0, atol=0)


def test_plane_set_fusion_widths():
    bound = torch.tensor([[0.0, 1.2], [0.0, 0.72], [0.0, 0.48]])
    points = _points(50) * 0.9
    common = dict(bound=bound, resolution=(0.24, 0.06), channels=5, init_std=0.1)
    torch.manual_seed(0)
    concat = PlaneSet(**common)
    torch.manual_seed(0)
    summed = PlaneSet(**common, fusion="sum")
    coarse = PlaneSet(**common, levels="coarse")
    fine = PlaneSet(**common, levels="fine")
    assert (concat.out_dim, summed.out_dim, coarse.out_dim, fine.out_dim) == (10, 5, 5, 5)
    assert list(coarse.levels) == ["coarse"] and list(fine.levels) == ["fine"]
    assert concat.levels["coarse"].grid == (5, 3, 2)
    assert concat.levels["fine"].grid == (20, 12, 8)
    features = concat.features(points)
    assert features.shape == (len(points), 10)
    torch.testing.assert_close(summed.features(points), features[:, :5] + features[:, 5:])
    assert coarse.numel_used() == 5 * (5 * 3 + 5 * 2 + 3 * 2)
    assert concat.numel_used() == coarse.numel_used() + fine.numel_used()
    with pytest.raises(ValueError, match="levels"):
        PlaneSet(**common, levels="middle")
