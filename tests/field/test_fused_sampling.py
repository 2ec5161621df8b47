"""plane_sampling: fused equals the reference: values, plane and point gradients, on
whole fields (every level of both plane sets in one op), grown fields and shared planes."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from eslam.config import FieldConfig
from eslam.field.fused_sampling import (
    FusedPlaneSampling,
    _layout_groups,
    _plane_gradient_scattered,
    _plane_gradient_sorted,
    bilinear_corners,
    sample_levels_fused,
)
from eslam.field.plane_sampling import sample_planes_reference
from eslam.field.planes import plane_shapes
from eslam.field.scene_field import SceneField

SMALL = FieldConfig(
    channels=4, geometry_resolution=(0.24, 0.12), appearance_resolution=(0.24, 0.08)
)
ROOM0 = torch.tensor([[-1.9, 7.9], [-2.2, 4.5], [-2.5, 2.3]])
"""An awkward bound: no side a multiple of the cell sizes."""


def _twins(config: FieldConfig, dtype: torch.dtype) -> tuple[SceneField, SceneField]:
    """A reference field with trained-like features and a fused one with its state."""
    reference = SceneField(
        dataclasses.replace(config, plane_sampling="reference"),
        ROOM0,
        torch.Generator().manual_seed(0),
    )
    with torch.no_grad():
        generator = torch.Generator().manual_seed(5)
        for param in reference.plane_parameters():
            param.add_(0.05 * torch.randn(param.shape, generator=generator) * (param != 0))
    fused = SceneField.from_state(
        dataclasses.replace(config, plane_sampling="fused"), reference.state_dict()
    )
    return reference.to(dtype), fused.to(dtype)


def _points(bound: torch.Tensor, count: int, dtype: torch.dtype) -> torch.Tensor:
    """Points in the bound grown by 20 % on every side (some read the border), plus
    points exactly on the bound's corners."""
    generator = torch.Generator().manual_seed(3)
    low, high = bound[:, 0].double(), bound[:, 1].double()
    margin = 0.2 * (high - low)
    unit = torch.rand(count, 3, generator=generator, dtype=torch.float64)
    points = low - margin + unit * (high - low + 2 * margin)
    corners = torch.stack((low, high, torch.stack((low[0], high[1], low[2]))))
    return torch.cat((points, corners)).to(dtype)


def _outputs(field: SceneField, points: torch.Tensor, with_rgb: bool = True):
    """Values and gradients of a fixed random functional of the field's outputs."""
    field.zero_grad(set_to_none=True)
    points = points.clone().requires_grad_(True)
    out = field.query(points, with_rgb=with_rgb)
    generator = torch.Generator().manual_seed(7)
    weights = torch.randn(out.sdf.shape, generator=generator, dtype=out.sdf.dtype)
    total = (out.sdf * weights).sum()
    if with_rgb:
        rgb_weights = torch.randn(out.rgb.shape, generator=generator, dtype=out.rgb.dtype)
        total = total + (out.rgb * rgb_weights).sum()
    total.backward()
    values = [out.sdf.detach()] + ([out.rgb.detach()] if with_rgb else [])
    plane_grads = [p.grad for p in field.plane_parameters() if p.grad is not None]
    return values, plane_grads, points.grad


def _assert_twins_agree(reference, fused, points, with_rgb=True, atol=1e-12):
    ref_values, ref_planes, ref_points = _outputs(reference, points, with_rgb)
    values, planes, point_grads = _outputs(fused, points, with_rgb)
    for a, b in zip(values, ref_values, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=atol)
    assert len(planes) == len(ref_planes) > 0
    for a, b in zip(planes, ref_planes, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=atol * max(1.0, b.abs().max().item()))
    torch.testing.assert_close(point_grads, ref_points, rtol=0, atol=atol * 100)


@pytest.mark.parametrize("with_rgb", [True, False])
def test_fused_field_equals_reference_in_float64(with_rgb):
    reference, fused = _twins(SMALL, torch.float64)
    assert fused.geometry.levels["fine"].planes.is_contiguous(memory_format=torch.channels_last)
    _assert_twins_agree(reference, fused, _points(reference.bound, 400, torch.float64), with_rgb)


def test_fused_field_equals_reference_in_float32():
    reference, fused = _twins(SMALL, torch.float32)
    points = _points(reference.bound, 400, torch.float32)
    _assert_twins_agree(reference, fused, points, atol=2e-5)


def test_fused_equals_reference_after_growth_and_with_shared_planes():
    """Grown levels have their own windows and new plane sizes; shared planes feed both
    decoders from the geometry set."""
    for config in (SMALL, dataclasses.replace(SMALL, shared_planes=True)):
        reference, fused = _twins(config, torch.float64)
        larger = torch.tensor([[-3.0, 8.5], [-2.2, 4.5], [-2.6, 3.0]])
        for field in (reference, fused):
            assert field.grow(larger, torch.Generator().manual_seed(9))
        level = fused.appearance.levels["fine"] if fused.appearance else None
        if level is not None:
            assert level.planes.is_contiguous(memory_format=torch.channels_last)
            assert not level._identity  # the grown level reads through its window
        _assert_twins_agree(reference, fused, _points(larger, 300, torch.float64))


def test_sdf_gradient_for_the_sdf_tracker_equals_reference():
    """The SDF tracker's use: frozen field, autograd.grad of the TSDF w.r.t. points."""
    reference, fused = _twins(SMALL, torch.float64)
    points = _points(reference.bound, 300, torch.float64)
    gradients = []
    for field in (reference, fused):
        field.requires_grad_(False)
        query = points.clone().requires_grad_(True)
        (gradient,) = torch.autograd.grad(field.query(query, with_rgb=False).sdf.sum(), query)
        gradients.append(gradient)
    torch.testing.assert_close(gradients[1], gradients[0], rtol=0, atol=1e-12)


def test_one_op_samples_levels_of_different_sizes_and_rejects_mismatched_lists():
    generator = torch.Generator().manual_seed(0)
    grids = [(3, 9, 2), (7, 5, 4), (2, 2, 2)]
    shapes = [plane_shapes(grid) for grid in grids]
    planes = [
        torch.randn(
            3,
            2 + k,
            max(h for h, _ in s),
            max(w for _, w in s),
            generator=generator,
            dtype=torch.float64,
        ).requires_grad_(True)
        for k, s in enumerate(shapes)
    ]
    coords = torch.rand(50, 3, generator=generator, dtype=torch.float64) * 3 - 1.5
    outputs = sample_levels_fused(coords, planes, shapes)
    for out, level_planes, level_shapes in zip(outputs, planes, shapes, strict=True):
        expected = sample_planes_reference(level_planes, level_shapes, coords)
        torch.testing.assert_close(out, expected, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="one plane tensor, shape and window"):
        sample_levels_fused(coords, planes, shapes[:2])


def test_backward_is_checked_by_gradcheck_and_refuses_double_backward():
    generator = torch.Generator().manual_seed(1)
    shapes = (plane_shapes((4, 3, 5)),)
    planes = torch.randn(3, 2, 5, 4, generator=generator, dtype=torch.float64)
    planes.requires_grad_(True)
    window = ((-1.2, 0.9), (-1.0, 1.0), (-0.8, 1.3))  # a grown level's box
    # away from cell edges and borders, where the bilinear map is smooth
    coords = (
        torch.rand(6, 3, generator=generator, dtype=torch.float64) * 1.6 - 0.8
    ).requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda c, p: FusedPlaneSampling.apply(shapes, (window,), c, p)[0], (coords, planes)
    )
    (out,) = FusedPlaneSampling.apply(shapes, (window,), coords, planes)
    (gradient,) = torch.autograd.grad(out.sum(), coords, create_graph=True)
    with pytest.raises(RuntimeError):  # no second derivatives: never a silent zero
        gradient.sum().backward()


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("grid", [(5, 4, 6), (5, 1, 6)])
def test_sorted_plane_gradient_equals_the_scattered_one(dtype, grid):
    """The CPU's sorted sum against the 12 scattered adds (the GPU's path): many points
    in few cells (long bags), rows nobody reads (empty bags, zero), padding beyond the
    true plane size, an axis one vertex wide (corners that coincide), no point at all."""
    generator = torch.Generator().manual_seed(2)
    shapes = plane_shapes(grid)
    height = max(h for h, _ in shapes) + 1
    width = max(w for _, w in shapes) + 2
    planes = torch.randn(3, 3, height, width, generator=generator, dtype=dtype)
    planes = planes.contiguous(memory_format=torch.channels_last)
    spread = torch.rand(40, 3, generator=generator, dtype=dtype) * 2.4 - 1.2
    crowd = 0.3 + 0.01 * torch.rand(60, 3, generator=generator, dtype=dtype)
    for coords in (torch.cat((spread, crowd)), spread[:0]):
        rows, weights, _ = bilinear_corners(coords, shapes, height, width)
        grad = torch.randn(len(coords), 3, generator=generator, dtype=dtype)
        layout = (3, height, width)
        sorted_sum = _plane_gradient_sorted(grad, rows, weights, layout)
        scattered = _plane_gradient_scattered(grad, rows, weights, layout)
        assert sorted_sum.shape == planes.shape
        # the same terms summed in another order: float32 rounding only
        atol = 1e-12 if dtype == torch.float64 else 1e-5
        torch.testing.assert_close(sorted_sum, scattered, rtol=0, atol=atol)
        if len(coords):
            assert sorted_sum.abs().sum() > 0
            assert torch.all(sorted_sum[:, :, :, shapes[0][1] + 1 :] == 0)  # padding


def test_levels_of_one_layout_share_their_look_ups_and_each_gets_its_own_gradient():
    """Two levels of one grid and window (a field's coarse geometry and appearance
    planes) are one group; a level of another window or size is its own. The grouped
    op's values and gradients equal each level sampled alone."""
    generator = torch.Generator().manual_seed(4)
    grid = (4, 3, 5)
    shapes = (plane_shapes(grid),) * 3 + (plane_shapes((6, 3, 5)),)
    window = ((-1.2, 0.9), (-1.0, 1.0), (-0.8, 1.3))
    windows = (None, None, window, None)
    channels = (2, 3, 2, 2)
    planes = [
        torch.randn(3, c, 5, 6, generator=generator, dtype=torch.float64)
        .contiguous(memory_format=torch.channels_last)
        .requires_grad_(True)
        for c in channels
    ]
    assert _layout_groups(shapes, windows, planes) == ((0, 1), (2,), (3,))
    coords = torch.rand(50, 3, generator=generator, dtype=torch.float64) * 2.4 - 1.2
    coords.requires_grad_(True)
    outs = sample_levels_fused(coords, planes, shapes, windows)
    weights = [torch.randn(out.shape, generator=generator, dtype=torch.float64) for out in outs]
    together = torch.autograd.grad(
        sum((o * w).sum() for o, w in zip(outs, weights, strict=True)), [coords, *planes]
    )
    alone = [torch.zeros_like(t) for t in together]
    for level in range(4):
        (out,) = sample_levels_fused(coords, [planes[level]], [shapes[level]], [windows[level]])
        torch.testing.assert_close(out, outs[level], rtol=0, atol=1e-12)
        grads = torch.autograd.grad((out * weights[level]).sum(), [coords, planes[level]])
        alone[0] += grads[0]
        alone[1 + level] += grads[1]
    for got, expected in zip(together, alone, strict=True):
        torch.testing.assert_close(got, expected, rtol=0, atol=1e-12)
