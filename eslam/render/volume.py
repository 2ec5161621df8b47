"""Volume rendering of a TSDF: sdf -> alpha -> weights -> depth, colour (docs/method.md section 2).

Pure functions over (N, S) tensors: N rays, S samples per ray, sorted front to back.
The TSDF value s is in units of the truncation distance T (s = metric SDF / T, in
[-1, 1], positive in free space in front of a surface).
"""

from __future__ import annotations

import torch

TRANSMITTANCE_EPSILON = 1e-10
"""Added to every (1 - alpha) in the transmittance product, as the release (and NeRF) do,
so a fully opaque sample (alpha = 1) does not zero the gradient of everything behind it."""

BELL_EPSILON = 1e-8
"""Guards the normalisation of bell weights on rays whose weights all underflow."""


def sdf_to_alpha(sdf: torch.Tensor, beta: torch.Tensor | float) -> torch.Tensor:
    """ESLAM's opacity of a sample from its TSDF (paper and release).

    sigma(s) = beta * sigmoid(-beta * s), alpha = 1 - exp(-sigma).

    The sample spacing does not appear (paper and release alike): alpha is the opacity
    of a sample, not of an interval, so it does not change when samples are denser.

    Args:
        sdf: (...) TSDF in units of T.
        beta: scalar sharpness (learnable; 10 at initialisation).

    Returns:
        (...) alpha in [0, 1).

    Example:
        s = 0, beta = 10: sigma = 10 * 0.5 = 5, alpha = 1 - exp(-5) = 0.99326.
    """
    sigma = beta * torch.sigmoid(-beta * sdf)
    return 1.0 - torch.exp(-sigma)


def alpha_to_weights(alpha: torch.Tensor) -> torch.Tensor:
    """Rendering weights: opacity times the transmittance of everything in front.

    w_i = alpha_i * prod_{j<i} (1 - alpha_j + eps), eps = TRANSMITTANCE_EPSILON
    (an exclusive cumulative product, the release's form).

    Args:
        alpha: (N, S) opacities, front to back.

    Returns:
        (N, S) weights; each ray's weights sum to at most 1 (up to eps).

    Example:
        alpha [0.5, 0.5, 1] -> w [0.5, 0.25, 0.25] (to within eps).
    """
    transmittance = torch.cumprod(1.0 - alpha + TRANSMITTANCE_EPSILON, dim=-1)
    shifted = torch.cat((torch.ones_like(alpha[..., :1]), transmittance[..., :-1]), dim=-1)
    return alpha * shifted


def sdf_to_weights(sdf: torch.Tensor, beta: torch.Tensor | float) -> torch.Tensor:
    """ESLAM's weights (the default density): ``alpha_to_weights(sdf_to_alpha(sdf, beta))``.

    Args:
        sdf: (N, S) TSDF in units of T, samples front to back.

    Returns:
        (N, S) weights.
    """
    return alpha_to_weights(sdf_to_alpha(sdf, beta))


def bell_weights(sdf: torch.Tensor, beta: torch.Tensor | float) -> torch.Tensor:
    """Bell-shaped weights peaking at the zero crossing (Co-SLAM style; an option only).

    w_i = b_i / sum_k b_k with b_i = sigmoid(beta s_i) * sigmoid(-beta s_i)
    (+ BELL_EPSILON in the denominator). Every ray's weights sum to 1. Co-SLAM writes
    sigmoid(s / tr) sigmoid(-s / tr) on an SDF in units of its truncation tr, i.e.
    beta = 1 / tr; here the sharpness is the field's beta. Co-SLAM's extra mask that
    keeps only the first surface crossing is not applied.

    Args:
        sdf: (N, S) TSDF in units of T.
        beta: scalar sharpness.

    Returns:
        (N, S) weights.

    Example:
        s = [1, 0, -1], beta = 10: b ~ [4.5e-5, 0.25, 4.5e-5] -> w ~ [1.8e-4, 0.99964, 1.8e-4].
    """
    bell = torch.sigmoid(beta * sdf) * torch.sigmoid(-beta * sdf)
    return bell / (bell.sum(dim=-1, keepdim=True) + BELL_EPSILON)


def composite(weights: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """Weighted sum along each ray: sum_i w_i v_i.

    Args:
        weights: (N, S).
        values: (N, S) (e.g. sample depths) or (N, S, C) (e.g. colours).

    Returns:
        (N,) or (N, C).

    Example:
        w [0.5, 0.25, 0.25], z [1, 2, 4] -> 0.5 + 0.5 + 1 = 2.
    """
    if values.dim() == weights.dim():
        return (weights * values).sum(dim=-1)
    return (weights.unsqueeze(-1) * values).sum(dim=-2)
