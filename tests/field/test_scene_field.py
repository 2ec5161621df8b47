"""SceneField: construction, queries, gradients, ablations, state round trip, fitting."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from eslam.config import FieldConfig
from eslam.field.scene_field import SceneField

SMALL = FieldConfig(
    channels=4, geometry_resolution=(0.24, 0.12), appearance_resolution=(0.24, 0.08)
)
BOUND = torch.tensor([[0.0, 1.0], [-0.5, 0.0], [0.0, 0.7]])
REPLICA_ROOM0 = torch.tensor([[-1.9, 7.9], [-2.2, 4.5], [-2.5, 2.3]])
"""Replica room0's scene bound in the release's configuration."""


def _field(config: FieldConfig = SMALL, bound: torch.Tensor = BOUND, seed: int = 0) -> SceneField:
    torch.manual_seed(seed)
    return SceneField(config, bound)


def _points(count: int, seed: int = 1) -> torch.Tensor:
    """World points in and around BOUND's fitted box [0, 1.2] x [-0.5, 0.22] x [0, 0.72]."""
    generator = torch.Generator().manual_seed(seed)
    unit = torch.rand(count, 3, generator=generator) * 1.2 - 0.1
    return unit * torch.tensor([1.2, 0.72, 0.72]) + torch.tensor([0.0, -0.5, 0.0])


def _expected_plane_count(field: SceneField) -> int:
    total = 0
    for param in field.plane_parameters():
        level = next(m for m in field.modules() if getattr(m, "planes", None) is param)
        nx, ny, nz = level.grid
        total += param.shape[1] * (nx * ny + nx * nz + ny * nz)
    return total


def test_bound_is_fitted_float32_buffer_in_state_dict():
    field = _field(bound=BOUND.double())
    expected = torch.tensor([[0.0, 1.2], [-0.5, 0.22], [0.0, 0.72]])
    assert field.bound.dtype == torch.float32
    torch.testing.assert_close(field.bound, expected, rtol=0, atol=1e-6)
    assert "bound" in field.state_dict()
    assert field.truncation == pytest.approx(0.06)
    assert field.geometry.levels["coarse"].grid == (5, 3, 3)
    assert field.geometry.levels["fine"].grid == (10, 6, 6)
    assert field.appearance.levels["fine"].grid == (15, 9, 9)


def test_query_shapes_and_ranges():
    field = _field()
    points = _points(1000)
    out = field.query(points)
    assert out.sdf.shape == (1000,) and out.rgb.shape == (1000, 3)
    assert out.sdf.min() >= -1 and out.sdf.max() <= 1
    assert out.rgb.min() >= 0 and out.rgb.max() <= 1
    no_rgb = field.query(points, with_rgb=False)
    assert no_rgb.rgb is None
    torch.testing.assert_close(no_rgb.sdf, out.sdf, rtol=0, atol=0)
    assert field.query(torch.zeros(0, 3)).sdf.shape == (0,)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        field.query(torch.zeros(5, 4))


def test_parameter_count_formula_and_replica_scale():
    field = _field(FieldConfig(), REPLICA_ROOM0)
    hidden = 32
    decoders = (64 * hidden + hidden + hidden + 1) + (64 * hidden + hidden + 3 * hidden + 3)
    assert field.parameter_count() == _expected_plane_count(field) + decoders + 1
    # docs/method.md section 1: about 6.8 M on Replica room0, almost all in the planes.
    assert 6.0e6 < field.parameter_count() < 7.5e6
    assert _expected_plane_count(field) > 0.99 * field.parameter_count()


def test_parameter_groups_cover_every_parameter_once():
    field = _field()
    groups = field.plane_parameters() + field.decoder_parameters()
    assert len(groups) == len({id(p) for p in groups}) == len(list(field.parameters()))
    assert len(field.plane_parameters()) == 4
    assert any(p is field.beta for p in field.decoder_parameters())


def test_gradients_reach_planes_decoders_and_beta():
    field = _field()
    out = field.query(_points(2000))
    loss = out.sdf.square().mean() + out.rgb.square().mean() + field.beta * out.sdf.mean()
    loss.backward()
    for param in field.plane_parameters() + field.decoder_parameters():
        assert param.grad is not None and param.grad.abs().sum() > 0


@pytest.mark.parametrize(
    ("changes", "geometry_width", "appearance_width", "plane_tensors"),
    [
        ({}, 8, 8, 4),
        ({"levels": "coarse"}, 4, 4, 2),
        ({"levels": "fine"}, 4, 4, 2),
        ({"level_fusion": "sum"}, 4, 4, 4),
        ({"shared_planes": True}, 8, 8, 2),
        ({"shared_planes": True, "levels": "fine"}, 4, 4, 1),
    ],
)
def test_ablations_feature_widths_and_counts(
    changes, geometry_width, appearance_width, plane_tensors
):
    config = dataclasses.replace(SMALL, **changes)
    field = _field(config)
    assert field.geometry_decoder.hidden[0].in_features == geometry_width
    assert field.appearance_decoder.hidden[0].in_features == appearance_width
    assert len(field.plane_parameters()) == plane_tensors
    assert (field.appearance is None) == config.shared_planes
    decoders = sum(p.numel() for p in field.decoder_parameters())
    assert field.parameter_count() == _expected_plane_count(field) + decoders
    out = field.query(_points(50))
    assert out.sdf.shape == (50,) and out.rgb.shape == (50, 3)


def test_ablation_parameter_counts_relate():
    full = _field().parameter_count()
    coarse = _field(dataclasses.replace(SMALL, levels="coarse")).parameter_count()
    fine = _field(dataclasses.replace(SMALL, levels="fine")).parameter_count()
    summed_field = _field(dataclasses.replace(SMALL, level_fusion="sum"))
    summed = summed_field.parameter_count()
    shared = _field(dataclasses.replace(SMALL, shared_planes=True))
    # Summing the levels halves the decoders' input: 4 x 32 fewer weights per decoder.
    assert summed == full - 2 * 4 * SMALL.decoder_hidden
    # Coarse-only and fine-only split the planes and each has the narrow decoders.
    narrow_decoders = sum(p.numel() for p in summed_field.decoder_parameters())
    assert coarse + fine == summed + narrow_decoders
    # Shared planes drop the appearance set; the decoders keep their widths.
    assert shared.parameter_count() == full - _field().appearance.numel_used()


def test_fixed_beta():
    field = _field(dataclasses.replace(SMALL, learn_beta=False, beta_init=7.5))
    assert not field.beta.requires_grad and field.beta.item() == 7.5
    assert all(p is not field.beta for p in field.decoder_parameters())


def test_state_dict_round_trip_reproduces_outputs():
    field = _field(seed=3)
    with torch.no_grad():
        for param in field.plane_parameters():
            param.add_(torch.randn_like(param) * (param != 0))
        field.beta.fill_(12.0)
    state = {k: v.clone() for k, v in field.state_dict().items()}
    loaded = SceneField.from_state(SMALL, state)
    points = _points(500)
    a, b = field.query(points), loaded.query(points)
    assert torch.equal(a.sdf, b.sdf) and torch.equal(a.rgb, b.rgb)
    assert torch.equal(loaded.bound, field.bound) and loaded.beta.item() == 12.0
    rebuilt = _field(SMALL, BOUND, seed=9)
    assert [p.shape for p in rebuilt.parameters()] == [p.shape for p in field.parameters()]
    with pytest.raises(RuntimeError):
        SceneField.from_state(dataclasses.replace(SMALL, channels=5), state)
    with pytest.raises(KeyError, match="bound"):
        SceneField.from_state(SMALL, {k: v for k, v in state.items() if k != "bound"})


def test_from_state_rebuilds_the_same_grids_for_awkward_bounds():
    for bound in (REPLICA_ROOM0, torch.tensor([[0.1, 4.9], [-2.4, 0.0], [0.0, 2.39]])):
        field = _field(FieldConfig(channels=1), bound)
        loaded = SceneField.from_state(field.config, field.state_dict())
        assert [p.shape for p in loaded.parameters()] == [p.shape for p in field.parameters()]


def test_fast_and_reference_fields_agree():
    fast = _field()
    reference = SceneField.from_state(
        dataclasses.replace(SMALL, plane_sampling="reference"), fast.state_dict()
    )
    assert reference.geometry.levels["fine"].sampling == "reference"
    points = _points(800)
    a, b = fast.query(points), reference.query(points)
    torch.testing.assert_close(a.sdf, b.sdf, rtol=0, atol=1e-6)
    torch.testing.assert_close(a.rgb, b.rgb, rtol=0, atol=1e-6)


def test_double_precision():
    field = _field()
    points = _points(300)
    single = field.query(points)
    field = field.double()
    double = field.query(points)
    assert double.sdf.dtype == torch.float64 and field.bound.dtype == torch.float64
    torch.testing.assert_close(double.sdf, single.sdf.double(), rtol=0, atol=1e-5)
    torch.testing.assert_close(double.rgb, single.rgb.double(), rtol=0, atol=1e-5)
    double.sdf.sum().backward()
    assert field.plane_parameters()[0].grad.dtype == torch.float64


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    field = _field()
    points = _points(300)
    cpu = field.query(points)
    gpu = field.to("cuda").query(points.cuda())
    torch.testing.assert_close(gpu.sdf.cpu(), cpu.sdf, rtol=0, atol=1e-5)


def test_fits_a_sphere_tsdf():
    """Adam makes the TSDF match an analytic sphere; frozen planes reach only ~0.14."""
    truncation, radius, centre = 0.06, 0.3, torch.tensor([0.5, 0.5, 0.5])
    torch.manual_seed(0)
    field = SceneField(
        FieldConfig(channels=8, truncation=truncation), torch.tensor([[0.0, 1.0]] * 3)
    )
    optimiser = torch.optim.Adam(
        [
            {"params": field.plane_parameters(), "lr": 0.05},
            {"params": field.decoder_parameters(), "lr": 0.01},
        ]
    )
    generator = torch.Generator().manual_seed(1)

    def sample(count: int) -> torch.Tensor:
        """Half uniform in the unit box, half within 2 T of the sphere."""
        uniform = torch.rand(count // 2, 3, generator=generator)
        direction = torch.nn.functional.normalize(torch.randn(count // 2, 3, generator=generator))
        offset = (torch.rand(count // 2, 1, generator=generator) * 2 - 1) * 2 * truncation
        return torch.cat((uniform, centre + direction * (radius + offset)))

    def target(points: torch.Tensor) -> torch.Tensor:
        distance = (points - centre).norm(dim=1) - radius
        return distance.clamp(-truncation, truncation) / truncation

    for _ in range(200):
        points = sample(4096)
        loss = (field.query(points, with_rgb=False).sdf - target(points)).abs().mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        points = sample(20000)
        error = (field.query(points, with_rgb=False).sdf - target(points)).abs().mean().item()
    # Measured 0.0072 (frozen planes: 0.136).
    assert error < 0.03


@pytest.mark.parametrize("sampling", ["fast", "reference", "fused"])
def test_nan_points_read_the_border_instead_of_crashing(sampling: str):
    config = dataclasses.replace(FieldConfig(), plane_sampling=sampling)
    bound = torch.tensor([[0.0, 2.0], [0.0, 2.0], [0.0, 2.0]])
    field = SceneField(config, bound, torch.Generator().manual_seed(0))
    points = torch.rand(50, 3, generator=torch.Generator().manual_seed(1)) * 2
    points[7] = float("nan")
    points[9, 2] = float("inf")
    out = field.query(points)
    assert bool(torch.isfinite(out.sdf).all()) and bool(torch.isfinite(out.rgb).all())
    clean = field.query(points[:5])  # the other points are unaffected
    assert torch.allclose(out.sdf[:5], clean.sdf, atol=1e-6)


def test_a_seeded_generator_gives_the_global_rngs_numbers():
    bound = torch.tensor([[0.0, 2.0], [0.0, 2.0], [0.0, 2.0]])
    torch.manual_seed(4)
    global_rng = SceneField(FieldConfig(), bound)
    state = torch.get_rng_state()
    seeded = SceneField(FieldConfig(), bound, torch.Generator().manual_seed(4))
    assert torch.equal(torch.get_rng_state(), state)  # the global generator is untouched
    for (name, a), (_, b) in zip(
        global_rng.state_dict().items(), seeded.state_dict().items(), strict=True
    ):
        assert torch.equal(a, b), name
