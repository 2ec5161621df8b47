"""SDF volume rendering: alpha, weights, bell weights and compositing on hand values."""

from __future__ import annotations

import math

import torch

from eslam.render.volume import (
    alpha_to_weights,
    bell_weights,
    composite,
    sdf_to_alpha,
    sdf_to_weights,
)


def test_sdf_to_alpha_hand_values() -> None:
    alpha = sdf_to_alpha(torch.tensor([0.0, 1.0, -1.0], dtype=torch.float64), 10.0)
    sigma_free = 10.0 / (1.0 + math.exp(10.0))  # 10 * sigmoid(-10) = 4.54e-4
    sigma_inside = 10.0 / (1.0 + math.exp(-10.0))
    expected = [1 - math.exp(-5.0), 1 - math.exp(-sigma_free), 1 - math.exp(-sigma_inside)]
    torch.testing.assert_close(alpha, torch.tensor(expected, dtype=torch.float64))


def test_sdf_to_alpha_accepts_a_tensor_beta_with_gradient() -> None:
    beta = torch.tensor(10.0, requires_grad=True)
    sdf_to_alpha(torch.tensor([0.0, 0.1]), beta).sum().backward()
    assert beta.grad is not None and torch.isfinite(beta.grad)


def test_alpha_to_weights_hand_values() -> None:
    weights = alpha_to_weights(torch.tensor([[0.5, 0.5, 1.0]], dtype=torch.float64))
    torch.testing.assert_close(
        weights, torch.tensor([[0.5, 0.25, 0.25]], dtype=torch.float64), atol=1e-9, rtol=0
    )
    first_opaque = alpha_to_weights(torch.tensor([[1.0, 0.7]], dtype=torch.float64))
    torch.testing.assert_close(
        first_opaque, torch.tensor([[1.0, 0.7e-10]], dtype=torch.float64), atol=1e-15, rtol=0
    )


def test_weights_behind_an_opaque_sample_keep_a_gradient() -> None:
    alpha = torch.tensor([[1.0, 0.5]], requires_grad=True)
    alpha_to_weights(alpha)[0, 1].backward()
    assert alpha.grad is not None and alpha.grad[0, 1] > 0


def test_sdf_to_weights_composes_alpha_and_weights() -> None:
    sdf = torch.tensor([[1.0, 0.5, 0.0, -0.5]])
    torch.testing.assert_close(sdf_to_weights(sdf, 10.0), alpha_to_weights(sdf_to_alpha(sdf, 10.0)))


def test_bell_weights_sum_to_one_and_peak_at_the_crossing() -> None:
    sdf = torch.tensor([[1.0, 0.0, -1.0], [0.9, 0.3, -0.3]])
    weights = bell_weights(sdf, 10.0)
    torch.testing.assert_close(weights.sum(dim=1), torch.ones(2))
    assert weights[0].argmax() == 1
    torch.testing.assert_close(weights[1, 1], weights[1, 2])
    b = 1 / (1 + math.exp(10)) / (1 + math.exp(-10))
    torch.testing.assert_close(weights[0, 0], torch.tensor(b / (0.25 + 2 * b)))


def test_composite_depth_and_colour() -> None:
    weights = torch.tensor([[0.5, 0.25, 0.25]])
    assert composite(weights, torch.tensor([[1.0, 2.0, 4.0]])).tolist() == [2.0]
    colours = torch.tensor([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]])
    assert composite(weights, colours).tolist() == [[0.5, 0.25, 0.25]]
