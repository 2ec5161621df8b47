"""Growing a SceneField's bound: old features stay in place, new area is fresh, state loads."""

from __future__ import annotations

import pytest
import torch

from eslam.config import FieldConfig
from eslam.field.planes import enclosing_bound, level_growth
from eslam.field.scene_field import SceneField

SMALL = FieldConfig(
    channels=4, geometry_resolution=(0.24, 0.12), appearance_resolution=(0.24, 0.08)
)
REPLICA_ROOM0 = torch.tensor([[-1.9, 7.9], [-2.2, 4.5], [-2.5, 2.3]])
"""An awkward bound: its grids' vertex spacings differ from the nominal cell sizes."""
LARGER = torch.tensor([[-3.0, 8.5], [-2.2, 4.5], [-2.6, 3.0]])
"""A box crossing REPLICA_ROOM0 on four sides, not on the y axis."""


def _trained_like(config: FieldConfig = SMALL, dtype: torch.dtype = torch.float32) -> SceneField:
    torch.manual_seed(0)
    field = SceneField(config, REPLICA_ROOM0).to(dtype)
    generator = torch.Generator().manual_seed(5)
    with torch.no_grad():  # features of a map after some training, not only the init noise
        for param in field.plane_parameters():
            noise = torch.randn(param.shape, generator=generator, dtype=dtype)
            param.add_(0.02 * noise * (param != 0))
    return field


def _inside(bound: torch.Tensor, count: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    generator = torch.Generator().manual_seed(2)
    unit = torch.rand(count, 3, generator=generator, dtype=torch.float64)
    bound = bound.double()
    return (bound[:, 0] + unit * (bound[:, 1] - bound[:, 0])).to(dtype)


def test_enclosing_bound_grows_by_whole_multiples_and_holds_the_old_one() -> None:
    old = SceneField(SMALL, REPLICA_ROOM0).bound
    new = enclosing_bound(old, LARGER, 0.24)
    sides = (new[:, 1] - new[:, 0]) / 0.24
    torch.testing.assert_close(sides, sides.round(), rtol=0, atol=1e-5)  # float32 input
    assert bool((new[:, 0] <= LARGER[:, 0].double()).all())
    assert bool((new[:, 1] >= LARGER[:, 1].double()).all())
    assert torch.equal(new[1], old[1].double()), "an axis not crossed keeps its exact sides"
    assert torch.equal(enclosing_bound(old, REPLICA_ROOM0 * 0.5, 0.24), old.double())


def test_level_growth_keeps_the_vertex_spacing() -> None:
    field = SceneField(SMALL, REPLICA_ROOM0)
    old = field.bound.double()
    new = enclosing_bound(old, LARGER, 0.24)
    level = field.appearance.levels["fine"]
    growth = level_growth(level.grid, level.window, old, new)
    spacing = (old[:, 1] - old[:, 0]) / (torch.tensor(level.grid) - 1)
    box = new[:, :1] + (growth.window + 1) / 2 * (new[:, 1:] - new[:, :1])
    new_spacing = (box[:, 1] - box[:, 0]) / (torch.tensor(growth.grid) - 1)
    torch.testing.assert_close(new_spacing, spacing.double(), rtol=0, atol=1e-12)
    torch.testing.assert_close(box[:, 0] + torch.tensor(growth.low) * spacing, old[:, 0])
    assert bool((box[:, 0] <= new[:, 0]).all()) and bool((box[:, 1] >= new[:, 1]).all())
    assert growth.low[1] == 0 and growth.grid[1] == level.grid[1]


def test_growth_keeps_queries_inside_the_old_bound() -> None:
    field = _trained_like()
    old_bound = field.bound.clone()
    points = _inside(old_bound, 4000)
    before = field.query(points)
    grids = [level.grid for level in field.geometry.levels.values()]
    generator = torch.Generator().manual_seed(9)
    assert field.grow(LARGER, generator)
    assert bool((field.bound[:, 0] <= LARGER[:, 0]).all())
    assert bool((field.bound[:, 1] >= LARGER[:, 1]).all())
    assert [level.grid for level in field.geometry.levels.values()] != grids
    after = field.query(points)
    torch.testing.assert_close(after.sdf, before.sdf, rtol=0, atol=1e-6)
    torch.testing.assert_close(after.rgb, before.rgb, rtol=0, atol=1e-6)
    assert not field.grow(old_bound, generator), "a box already inside changes nothing"


def test_growth_is_exact_up_to_rounding_in_double_precision() -> None:
    field = _trained_like(dtype=torch.float64)
    points = _inside(field.bound, 2000, torch.float64)
    before = field.query(points)
    field.grow(LARGER.double(), torch.Generator().manual_seed(9).manual_seed(9))
    field.grow(LARGER.double() + 1.3, torch.Generator().manual_seed(3))  # twice
    after = field.query(points)
    torch.testing.assert_close(after.sdf, before.sdf, rtol=0, atol=1e-12)
    torch.testing.assert_close(after.rgb, before.rgb, rtol=0, atol=1e-12)


def test_new_area_is_initialised_like_fresh_planes_from_the_generator() -> None:
    fields = [_trained_like(), _trained_like(), _trained_like()]
    level = fields[0].appearance.levels["fine"]
    growth = level_growth(
        level.grid,
        level.window,
        fields[0].bound,
        enclosing_bound(fields[0].bound, LARGER, SMALL.bound_multiple),
    )
    for field, seed in zip(fields, (4, 4, 5), strict=True):
        field.grow(LARGER, torch.Generator().manual_seed(seed))
    h = level.shapes[0][0]
    planes = level.planes.detach()
    # the xy plane's new columns (x below the old bound) hold fresh normal(0, 0.01) features
    fresh = planes[0, :, :h, : growth.low[0]]
    assert growth.low[0] >= 10
    assert abs(float(fresh.std()) - SMALL.init_std) < 0.001 and abs(float(fresh.mean())) < 0.001
    assert float(planes[level.padding.expand_as(planes)].abs().sum()) == 0.0
    same = zip(fields[0].plane_parameters(), fields[1].plane_parameters(), strict=True)
    assert all(torch.equal(a, b) for a, b in same), "the same seed gives the same new features"
    assert not torch.equal(fields[0].plane_parameters()[-1], fields[2].plane_parameters()[-1])


def test_grown_field_round_trips_through_its_state() -> None:
    field = _trained_like()
    field.grow(LARGER, torch.Generator().manual_seed(1))
    state = {k: v.clone() for k, v in field.state_dict().items()}
    assert {"geometry.levels.fine.window", "geometry.levels.fine.vertices"} <= set(state)
    loaded = SceneField.from_state(SMALL, state)
    assert [p.shape for p in loaded.parameters()] == [p.shape for p in field.parameters()]
    points = _inside(LARGER, 1000)
    a, b = field.query(points), loaded.query(points)
    assert torch.equal(a.sdf, b.sdf) and torch.equal(a.rgb, b.rgb)
    # a state saved before levels had windows (older map.pt) still loads
    fresh = _trained_like()
    old_style = {
        k: v for k, v in fresh.state_dict().items() if not k.endswith(("window", "vertices"))
    }
    again = SceneField.from_state(SMALL, old_style)
    assert torch.equal(again.query(points).sdf, fresh.query(points).sdf)


def test_growth_frees_gradients_for_new_parameters() -> None:
    field = _trained_like()
    field.grow(LARGER, torch.Generator().manual_seed(1))
    outside_old = torch.tensor([[-2.8, 0.0, 0.0], [8.3, 1.0, 2.8]])
    field.query(outside_old).sdf.sum().backward()
    for level in field.geometry.levels.values():
        grad = level.planes.grad
        assert grad is not None and float(grad.abs().sum()) > 0
        assert float(grad[level.padding.expand_as(grad)].abs().sum()) == 0.0


@pytest.mark.parametrize("levels", ["coarse", "fine"])
def test_growth_with_one_level_and_shared_planes(levels: str) -> None:
    config = FieldConfig(
        channels=2,
        geometry_resolution=(0.24, 0.12),
        appearance_resolution=(0.24, 0.08),
        levels=levels,
        shared_planes=True,
    )
    field = _trained_like(config)
    points = _inside(field.bound, 500)
    before = field.query(points)
    field.grow(LARGER, torch.Generator().manual_seed(1))
    torch.testing.assert_close(field.query(points).sdf, before.sdf, rtol=0, atol=1e-6)


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_growth_on_cuda_matches_cpu() -> None:
    cpu = _trained_like()
    cuda = _trained_like().to("cuda")
    points = _inside(cpu.bound, 2000)
    before = cuda.query(points.cuda())
    cpu.grow(LARGER, torch.Generator().manual_seed(1))
    cuda.grow(LARGER, torch.Generator(device="cuda").manual_seed(1))
    assert torch.equal(cuda.bound.cpu(), cpu.bound)
    after = cuda.query(points.cuda())
    torch.testing.assert_close(after.sdf, before.sdf, rtol=0, atol=1e-6)
    wide = _inside(LARGER, 2000)
    loaded = SceneField.from_state(SMALL, {k: v.cpu() for k, v in cuda.state_dict().items()})
    torch.testing.assert_close(loaded.query(wide).sdf, cuda.query(wide.cuda()).sdf.cpu())
