"""The shared loss: TSDF masks and reductions on hand-made rays, depth/colour terms, outliers."""

from __future__ import annotations

import pytest
import torch

from eslam.config import LossConfig, LossWeights
from eslam.losses import (
    compute_losses,
    depth_noise_scale,
    depth_noise_weights,
    masked_mean,
    sdf_loss_terms,
)
from eslam.types import RayBatch, RenderOutput

F64 = torch.float64
T = 0.1

# Ray 1: D = 1. |z - D| = 0.5, 0.15 (front) | 0.05 (tail) 0.02, 0.03 (middle) 0.08 (tail)
# | 0.2 (behind). Ray 2: D = 2, three front samples, one at the surface, three behind.
Z = torch.tensor(
    [[0.5, 0.85, 0.95, 0.98, 1.03, 1.08, 1.2], [0.5, 1.0, 1.5, 2.0, 2.5, 2.6, 2.7]], dtype=F64
)
S = torch.tensor(
    [[0.9, 0.8, 0.3, 0.1, -0.2, -0.5, -1.0], [1.0, 0.8, 0.5, 0.0, -1.0, -1.0, -1.0]], dtype=F64
)
D = torch.tensor([1.0, 2.0], dtype=F64)
# Free space (s - 1)^2: ray 1 [0.01, 0.04], ray 2 [0, 0.04, 0.25].
# Middle (z + s T - D)^2: ray 1 [1e-4, 1e-4], ray 2 [0]. Tail: ray 1 [4e-4, 9e-4].


def close(value: torch.Tensor, expected: float) -> None:
    assert value.shape == ()
    assert value.item() == pytest.approx(expected, abs=1e-12)


def test_masked_mean_hand_values() -> None:
    values = torch.tensor([[1.0, 3.0], [5.0, 0.0]])
    mask = torch.tensor([[True, True], [True, False]])
    close(masked_mean(values, mask, "points"), 3.0)
    close(masked_mean(values, mask, "per_ray"), 3.5)
    with pytest.raises(ValueError, match="reduction"):
        masked_mean(values, mask, "rays")


def test_masked_mean_with_ray_weights_hand_values() -> None:
    values = torch.tensor([[1.0, 3.0], [5.0, 0.0]], dtype=F64)
    mask = torch.tensor([[True, True], [True, False]])
    weights = torch.tensor([1.0, 3.0], dtype=F64)
    close(masked_mean(values, mask, "points", weights), (1.0 + 3.0 + 15.0) / 5.0)
    close(masked_mean(values, mask, "per_ray", weights), (2.0 + 15.0) / 4.0)
    # A ray with no selected sample carries no weight; all-zero weights give 0, not nan.
    empty = torch.tensor([[True, True], [False, False]])
    close(masked_mean(values, empty, "per_ray", weights), 2.0)
    close(masked_mean(values, mask, "points", torch.zeros(2, dtype=F64)), 0.0)
    close(masked_mean(values, mask, "per_ray", torch.zeros(2, dtype=F64)), 0.0)


@pytest.mark.parametrize("reduction", ["points", "per_ray"])
def test_equal_ray_weights_give_the_plain_means(reduction: str) -> None:
    config = LossConfig(reduction=reduction)
    plain = sdf_loss_terms(S, Z, D, T, config)
    for weight in (1.0, 7.0):
        weighted = sdf_loss_terms(S, Z, D, T, config, ray_weights=torch.full((2,), weight))
        for a, b in zip(plain, weighted, strict=True):
            assert b.item() == pytest.approx(a.item(), rel=1e-12)


def test_unequal_ray_weights_reach_every_tsdf_term() -> None:
    weights = torch.tensor([1.0, 3.0], dtype=F64)
    per_ray = sdf_loss_terms(S, Z, D, T, LossConfig(reduction="per_ray"), ray_weights=weights)
    close(per_ray.free_space, (0.025 + 3.0 * 0.29 / 3) / 4.0)
    close(per_ray.trunc_middle, (1e-4 + 3.0 * 0.0) / 4.0)
    close(per_ray.trunc_tail, 6.5e-4)
    points = sdf_loss_terms(S, Z, D, T, LossConfig(reduction="points"), ray_weights=weights)
    close(points.free_space, (0.01 + 0.04 + 3.0 * (0.0 + 0.04 + 0.25)) / (2 + 3.0 * 3))
    close(points.trunc_middle, (1e-4 + 1e-4 + 3.0 * 0.0) / (2 + 3.0 * 1))


def test_depth_noise_weights_are_inverse_variances() -> None:
    depth = torch.tensor([0.75, 1.5, 3.0, 0.0], dtype=F64)
    weights = depth_noise_weights(depth)
    assert (weights[:3] / weights[1]).tolist() == pytest.approx([16.0, 1.0, 1.0 / 16.0])
    assert weights[3] == 0.0
    # sigma(D) / sigma(z0) = (D / z0)^2: w is (sigma(z0) / sigma(D))^2 up to a common factor.
    assert torch.allclose(weights[:3] * 1.5**4, depth_noise_scale(depth[:3], 1.5).pow(-2))


def test_ray_weights_weigh_depth_and_tsdf_terms_but_not_colour() -> None:
    z = torch.tensor([[0.5, 1.0], [1.5, 2.0]], dtype=F64)
    measured_rgb = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], dtype=F64)
    rendered_rgb = torch.tensor([[0.3, 0.0, 0.0], [1.0, 0.4, 1.0]], dtype=F64)
    output = render_output([1.1, 1.8], rendered_rgb, z)
    rays = rays_of([1.0, 2.0], measured_rgb)
    weights = depth_noise_weights(rays.depth)  # [1, 1/16]: the far ray counts less
    plain = compute_losses(output, rays, LossWeights(), T, LossConfig())
    noisy = compute_losses(output, rays, LossWeights(), T, LossConfig(), ray_weights=weights)
    close(noisy.depth, (1.0 * 0.01 + 0.04 / 16.0) / (1.0 + 1.0 / 16.0))
    close(noisy.colour, plain.colour.item())
    # The TSDF terms get the weights too (the fixture's rays: D = 1 and 2, weights 1, 1/16).
    fixture = RenderOutput(depth=D, rgb=None, z_vals=Z, sdf=S, weights=torch.zeros_like(S))
    tsdf = compute_losses(
        fixture,
        rays_of([1.0, 2.0], torch.zeros(2, 3)),
        LossWeights(),
        T,
        LossConfig(),
        ray_weights=weights,
    )
    close(tsdf.free_space, (0.025 + 0.29 / 3 / 16.0) / (1.0 + 1.0 / 16.0))
    close(tsdf.trunc_middle, 1e-4 / (1.0 + 1.0 / 16.0))
    close(tsdf.trunc_tail, 6.5e-4)  # only ray 1 has tail samples
    # Outlier rejection and weights combine: the rejected ray's weight drops out.
    far = compute_losses(
        render_output([1.1, 1.8, 11.0], None, torch.cat([z, z[:1]])),
        rays_of([1.0, 2.0, 1.0], torch.zeros(3, 3)),
        LossWeights(),
        T,
        LossConfig(),
        outlier_factor=10.0,
        ray_weights=torch.tensor([1.0, 1.0 / 16.0, 1.0], dtype=F64),
    )
    close(far.depth, (0.01 + 0.04 / 16.0) / (1.0 + 1.0 / 16.0))


def test_one_ray_terms() -> None:
    terms = sdf_loss_terms(S[:1], Z[:1], D[:1], T, LossConfig())
    close(terms.free_space, 0.025)
    close(terms.trunc_middle, 1e-4)
    close(terms.trunc_tail, 6.5e-4)


def test_per_ray_reduction_paper() -> None:
    terms = sdf_loss_terms(S, Z, D, T, LossConfig(reduction="per_ray"))
    close(terms.free_space, (0.025 + 0.29 / 3) / 2)
    close(terms.trunc_middle, (1e-4 + 0.0) / 2)
    close(terms.trunc_tail, 6.5e-4)  # only ray 1 has tail samples


def test_points_reduction_release() -> None:
    terms = sdf_loss_terms(S, Z, D, T, LossConfig(reduction="points"))
    close(terms.free_space, (0.01 + 0.04 + 0.0 + 0.04 + 0.25) / 5)
    close(terms.trunc_middle, (1e-4 + 1e-4 + 0.0) / 3)
    close(terms.trunc_tail, 6.5e-4)


def test_single_band_ablation() -> None:
    terms = sdf_loss_terms(S[:1], Z[:1], D[:1], T, LossConfig(single_band=True))
    close(terms.trunc_middle, (4e-4 + 1e-4 + 1e-4 + 9e-4) / 4)
    close(terms.trunc_tail, 0.0)
    close(terms.free_space, 0.025)


def test_middle_fraction_moves_the_split() -> None:
    terms = sdf_loss_terms(S[:1], Z[:1], D[:1], T, LossConfig(middle_fraction=0.6))
    close(terms.trunc_middle, (4e-4 + 1e-4 + 1e-4) / 3)
    close(terms.trunc_tail, 9e-4)


@pytest.mark.parametrize("reduction", ["per_ray", "points"])
def test_empty_sets_give_zero_and_finite_gradients(reduction: str) -> None:
    sdf = torch.tensor([[-1.0, -1.0]], dtype=F64, requires_grad=True)
    z = torch.tensor([[1.5, 1.6]], dtype=F64)  # all behind D + T
    terms = sdf_loss_terms(
        sdf, z, torch.tensor([1.0], dtype=F64), T, LossConfig(reduction=reduction)
    )
    for value in terms:
        close(value, 0.0)
    sum(terms).backward()
    assert torch.all(sdf.grad == 0)


def test_ray_mask_leaves_rays_out() -> None:
    keep = torch.tensor([True, False])
    masked = sdf_loss_terms(S, Z, D, T, LossConfig(), ray_mask=keep)
    alone = sdf_loss_terms(S[:1], Z[:1], D[:1], T, LossConfig())
    for a, b in zip(masked, alone, strict=True):
        close(a, b.item())


def render_output(depth: list[float], rgb: torch.Tensor | None, z: torch.Tensor) -> RenderOutput:
    n, s = z.shape
    return RenderOutput(
        depth=torch.tensor(depth, dtype=F64, requires_grad=True),
        rgb=rgb,
        z_vals=z,
        sdf=torch.zeros(n, s, dtype=F64, requires_grad=True),
        weights=torch.zeros(n, s, dtype=F64),
    )


def rays_of(depth: list[float], rgb: torch.Tensor) -> RayBatch:
    n = len(depth)
    return RayBatch(torch.zeros(n, 3), torch.zeros(n, 3), torch.tensor(depth, dtype=F64), rgb)


def test_depth_colour_and_total() -> None:
    z = torch.tensor([[0.5, 1.0], [1.5, 2.0]], dtype=F64)
    measured_rgb = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], dtype=F64)
    rendered_rgb = torch.tensor([[0.3, 0.0, 0.0], [1.0, 0.4, 1.0]], dtype=F64, requires_grad=True)
    output = render_output([1.1, 1.8], rendered_rgb, z)
    rays = rays_of([1.0, 2.0], measured_rgb)
    weights = LossWeights(free_space=2.0, trunc_middle=3.0, trunc_tail=5.0, depth=7.0, colour=11.0)
    terms = compute_losses(output, rays, weights, T, LossConfig())
    close(terms.depth, (0.01 + 0.04) / 2)
    close(terms.colour, (0.09 + 0.36) / 6)  # mean over rays and channels
    # sdf = 0 everywhere: front samples 0.5 (ray 1) and 1.5 (ray 2) give (0 - 1)^2 = 1;
    # surface samples at z = D give a zero residual.
    close(terms.free_space, 1.0)
    close(terms.trunc_middle, 0.0)
    expected = 2.0 * 1.0 + 7.0 * 0.025 + 11.0 * 0.075
    close(terms.total, expected)
    terms.total.backward()
    assert output.depth.grad is not None and torch.all(output.depth.grad != 0)
    assert output.sdf.grad is not None and output.sdf.grad[0, 0] != 0
    assert rendered_rgb.grad is not None and rendered_rgb.grad[0, 0] > 0


def test_no_colour_gives_zero_colour_term() -> None:
    z = torch.tensor([[0.5, 1.0]], dtype=F64)
    output = render_output([1.2], None, z)
    terms = compute_losses(
        output, rays_of([1.0], torch.zeros(1, 3)), LossWeights(), T, LossConfig()
    )
    close(terms.colour, 0.0)
    close(terms.total, 5.0 * 1.0 + 0.1 * 0.04)


def test_outlier_rejection_drops_a_ray_from_every_term() -> None:
    # Residuals 0.1, -0.2, 0.1, 10: median (lower middle) 0.1, threshold 1 -> drop ray 4.
    z = torch.tensor([[0.5, 1.0], [1.5, 2.0], [0.5, 1.0], [0.0, 1.0]], dtype=F64)
    measured_rgb = torch.zeros(4, 3, dtype=F64)
    rendered_rgb = torch.zeros(4, 3, dtype=F64)
    rendered_rgb[3] = 1.0
    rendered_rgb.requires_grad_(True)
    output = render_output([1.1, 1.8, 1.1, 11.0], rendered_rgb, z)
    rays = rays_of([1.0, 2.0, 1.0, 1.0], measured_rgb)
    kept = compute_losses(output, rays, LossWeights(), T, LossConfig(), outlier_factor=10.0)
    close(kept.depth, (0.01 + 0.04 + 0.01) / 3)
    close(kept.colour, 0.0)
    close(kept.free_space, 1.0)
    kept.total.backward()
    assert output.depth.grad[3] == 0 and torch.all(output.depth.grad[:3] != 0)
    assert torch.all(output.sdf.grad[3] == 0)
    everything = compute_losses(output, rays, LossWeights(), T, LossConfig())
    close(everything.depth, (0.01 + 0.04 + 0.01 + 100.0) / 4)
    close(everything.colour, 1.0 / 4)


def test_rays_without_depth_are_left_out() -> None:
    z = torch.tensor([[0.5, 1.0], [0.5, 1.0]], dtype=F64)
    output = render_output([1.1, 3.0], None, z)
    terms = compute_losses(
        output, rays_of([1.0, 0.0], torch.zeros(2, 3)), LossWeights(), T, LossConfig()
    )
    close(terms.depth, 0.01)
    close(terms.free_space, 1.0)
