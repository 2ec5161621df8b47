"""Ray sampling: depth-guided, uniform, box intersection and importance sampling."""

from __future__ import annotations

import pytest
import torch

from eslam.render.sampling import (
    depth_guided_samples,
    importance_samples,
    midpoint_edges,
    ray_box_exit,
    ray_box_intersection,
    stratified_offsets,
    uniform_samples,
)

T = 0.06


def gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def test_depth_guided_hand_values_without_perturb() -> None:
    z = depth_guided_samples(torch.tensor([2.0], dtype=torch.float64), 32, 8, T)
    stratified = 2.4 * torch.arange(32, dtype=torch.float64) / 31
    surface = 1.91 + 0.18 * torch.arange(8, dtype=torch.float64) / 7
    expected = torch.sort(torch.cat((stratified, surface))).values
    assert z.shape == (1, 40)
    torch.testing.assert_close(z[0], expected)
    assert z[0, 0] == 0.0
    assert z[0, -1] == pytest.approx(2.4)
    # The surface set is exactly evenly spaced, 0.18 / 7 apart, centred on D.
    band = z[0][(z[0] >= 1.91 - 1e-12) & (z[0] <= 2.09 + 1e-12)]
    assert set(band.tolist()) >= set(surface.tolist())


def test_depth_guided_counts_sorted_and_ranges_when_perturbed() -> None:
    depth = torch.linspace(0.5, 4.0, 50)
    z = depth_guided_samples(depth, 32, 8, T, perturb=True, generator=gen())
    assert z.shape == (50, 40)
    assert torch.all(z[:, 1:] >= z[:, :-1])
    d = depth[:, None]
    stratified = (z >= 0) & (z <= 1.2 * d)
    surface = (z >= d - 1.5 * T) & (z <= d + 1.5 * T)
    assert torch.all(stratified | surface)
    assert torch.all(surface.sum(dim=1) >= 8)
    assert torch.all(stratified.sum(dim=1) >= 32)


def test_depth_guided_is_deterministic_given_a_generator() -> None:
    depth = torch.full((5,), 1.5)
    a = depth_guided_samples(depth, 32, 8, T, perturb=True, generator=gen(3))
    b = depth_guided_samples(depth, 32, 8, T, perturb=True, generator=gen(3))
    c = depth_guided_samples(depth, 32, 8, T, perturb=True, generator=gen(4))
    assert torch.equal(a, b)
    assert not torch.equal(a, c)


def test_depth_guided_without_surface_samples_is_all_stratified() -> None:
    z = depth_guided_samples(torch.tensor([1.0]), 40, 0, T)
    torch.testing.assert_close(z[0], torch.linspace(0.0, 1.2, 40))
    with pytest.raises(ValueError, match="n_surface"):
        depth_guided_samples(torch.tensor([1.0]), 40, -1, T)


def test_uniform_samples_evenly_spaced_and_jittered_in_bins() -> None:
    near, far = torch.zeros(1000), torch.ones(1000)
    torch.testing.assert_close(
        uniform_samples(near[:1], far[:1], 5, perturb=False)[0],
        torch.tensor([0.0, 0.25, 0.5, 0.75, 1.0]),
    )
    z = uniform_samples(near, far, 5, perturb=True, generator=gen())
    lower = torch.tensor([0.0, 0.125, 0.375, 0.625, 0.875])
    upper = torch.tensor([0.125, 0.375, 0.625, 0.875, 1.0])
    assert torch.all((z >= lower) & (z <= upper))
    # Jitter fills each bin: the spread covers most of it.
    assert torch.all(z.amax(dim=0) - z.amin(dim=0) > 0.9 * (upper - lower))
    shifted = uniform_samples(torch.tensor([2.0]), torch.tensor([4.0]), 3, perturb=False)
    torch.testing.assert_close(shifted[0], torch.tensor([2.0, 3.0, 4.0]))


def test_single_stratified_sample_is_the_midpoint() -> None:
    like = torch.zeros(1)
    assert stratified_offsets(2, 1, False, None, like).tolist() == [[0.5], [0.5]]
    with pytest.raises(ValueError, match="at least one"):
        stratified_offsets(2, 0, False, None, like)


def test_ray_box_exit_from_the_centre_of_a_unit_box() -> None:
    bound = torch.tensor([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])
    axes = torch.cat((torch.eye(3), -torch.eye(3)))
    origins = torch.full((6, 3), 0.5)
    near, far = ray_box_intersection(origins, axes, bound)
    torch.testing.assert_close(far, torch.full((6,), 0.5))
    torch.testing.assert_close(near, torch.zeros(6))
    torch.testing.assert_close(ray_box_exit(origins, 2 * axes, bound), torch.full((6,), 0.25))
    diagonal = ray_box_exit(origins[:1], torch.tensor([[1.0, 1.0, 0.25]]), bound)
    torch.testing.assert_close(diagonal, torch.tensor([0.5]))


def test_ray_box_from_outside_and_misses() -> None:
    bound = torch.tensor([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])
    origins = torch.tensor([[-1.0, 0.5, 0.5], [-1.0, 2.0, 0.5], [2.0, 0.5, 0.5]])
    directions = torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    near, far = ray_box_intersection(origins, directions, bound)
    assert (near[0].item(), far[0].item()) == (1.0, 2.0)
    assert far[1] <= near[1]  # parallel to the y slab, outside it
    assert far[2] <= near[2]  # box behind the ray


def test_midpoint_edges_hand_values() -> None:
    edges = midpoint_edges(torch.tensor([[0.0, 1.0, 3.0]]))
    torch.testing.assert_close(edges, torch.tensor([[0.0, 0.5, 2.0, 3.0]]))


def test_importance_uniform_weights_give_uniform_samples() -> None:
    edges = torch.tensor([[0.0, 1.0, 2.0]])
    z = importance_samples(edges, torch.tensor([[1.0, 1.0]]), 4, perturb=False)
    torch.testing.assert_close(z, torch.tensor([[0.25, 0.75, 1.25, 1.75]]))
    zero = importance_samples(edges, torch.zeros(1, 2), 4, perturb=False)
    torch.testing.assert_close(zero, z)


def test_importance_inverse_cdf_hand_values() -> None:
    # pdf [0.25, 0.75]; u = 0.125, 0.375, 0.625, 0.875.
    z = importance_samples(torch.tensor([[0.0, 1.0, 2.0]]), torch.tensor([[1.0, 3.0]]), 4, False)
    expected = torch.tensor([[0.5, 1.0 + 1 / 6, 1.5, 1.0 + 5 / 6]])
    torch.testing.assert_close(z, expected, atol=1e-4, rtol=0)


def test_importance_one_hot_weight_puts_every_sample_in_its_bin() -> None:
    edges = torch.linspace(0.0, 4.0, 9).expand(3, 9)
    weights = torch.zeros(3, 8)
    weights[:, 5] = 0.7
    for perturb in (False, True):
        z = importance_samples(edges, weights, 16, perturb, gen())
        assert z.shape == (3, 16)
        assert torch.all((z >= 2.5) & (z <= 3.0))
        assert torch.all(z[:, 1:] >= z[:, :-1])


def test_importance_perturbed_is_seeded_and_checks_shapes() -> None:
    edges, weights = torch.tensor([[0.0, 1.0, 2.0]]), torch.tensor([[1.0, 1.0]])
    a = importance_samples(edges, weights, 8, True, gen(1))
    assert torch.equal(a, importance_samples(edges, weights, 8, True, gen(1)))
    # Stratified u: sample k lies in [k / 8, (k + 1) / 8) of the (uniform) cdf.
    k = torch.arange(8)
    assert torch.all((a[0] >= k / 4) & (a[0] <= (k + 1) / 4))
    with pytest.raises(ValueError, match="B \\+ 1 edges"):
        importance_samples(torch.zeros(1, 2), torch.zeros(1, 2), 4, False)
