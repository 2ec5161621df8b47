"""The one loss function tracking and mapping both call (docs/method.md section 3).

For a ray with measured depth D and a sample at z with predicted TSDF s (units of T):

- free space, z < D - T: (s - 1)^2;
- truncation middle, |z - D| < f T (f = 0.4, paper): (z + s T - D)^2;
- truncation tail, f T <= |z - D| <= T: the same residual;
- behind the surface, z > D + T: no loss (release);
- depth: (D_hat - D)^2 per ray; colour: (C_hat - C)^2 per ray and channel.

Tracking and mapping differ only in the weights they pass and in tracking's outlier
rejection. Optional per-ray weights (mapping's depth-noise model,
:func:`depth_noise_weights`) turn the four depth-derived terms into weighted means.
Everything is differentiable and free of host synchronisation.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from eslam.config import LossConfig, LossWeights
from eslam.types import LossTerms, RayBatch, RenderOutput


class SdfTerms(NamedTuple):
    """The three TSDF loss terms (scalar tensors, unweighted)."""

    free_space: torch.Tensor
    trunc_middle: torch.Tensor
    trunc_tail: torch.Tensor


def depth_noise_scale(depth: torch.Tensor, reference: float | None) -> torch.Tensor:
    """sigma(z) / sigma(z0) = (z / z0)^2 for depths z (metres), elementwise: the standard
    deviation of structured-light and stereo depth grows with the square of the distance
    (Khoshelham and Elberink 2012, Kinect v1: sigma(z) ~ 1.4 mm z^2 / m^2; the same law
    for disparity-based sensors), so a residual divided by it is in units of the noise
    at z0. Ones when ``reference`` is None (every depth alike)."""
    if reference is None:
        return torch.ones_like(depth)
    return (depth / reference).square()


def depth_noise_weights(depth: torch.Tensor) -> torch.Tensor:
    """Relative inverse-variance weights w = D^-4 (units m^-4) of squared
    depth residuals, for measured depths D (N,) in metres; 0 where D <= 0 (no depth).

    Depth noise grows as sigma(D) ~ D^2 (:func:`depth_noise_scale`), so the inverse
    variance goes as D^-4. The weights enter weighted means (:func:`masked_mean`,
    :func:`compute_losses`), where any common factor (a reference depth z0, the sensor's
    noise at 1 m) cancels: only the balance between near and far rays changes.
    """
    safe = depth.clamp(min=1e-6)
    return torch.where(depth > 0, safe.pow(-4), torch.zeros_like(depth))


def ratio_or_zero(numerator: torch.Tensor, denominator: torch.Tensor) -> torch.Tensor:
    """numerator / denominator, and 0 where the denominator is 0 (an empty mean), for a
    non-negative denominator (a count or a sum of weights); no host synchronisation."""
    return numerator / torch.where(denominator > 0, denominator, torch.ones_like(denominator))


def masked_mean(
    values: torch.Tensor,
    mask: torch.Tensor,
    reduction: str,
    ray_weights: torch.Tensor | None = None,
) -> torch.Tensor:
    """Mean of ``values`` over the samples selected by ``mask``; 0 when none is selected.

    "points" (release): sum_{r,i} m_ri v_ri / sum_{r,i} m_ri.
    "per_ray" (paper): per ray mean_r = sum_i m_ri v_ri / sum_i m_ri over the rays with at
    least one selected sample, then the mean of mean_r over those rays.
    With ``ray_weights`` w_r both become weighted means: sum w_r m_ri v_ri / sum w_r m_ri
    and sum_r w_r mean_r / sum_r w_r over the rays with a selected sample (all w_r = 1
    gives the unweighted means).

    Args:
        values: (N, S).
        mask: (N, S) bool.
        reduction: "per_ray" or "points".
        ray_weights: optional (N,) non-negative weights, one per ray.

    Returns:
        Scalar tensor.

    Example:
        values [[1, 3], [5, 0]], mask [[T, T], [T, F]]: points (1+3+5)/3 = 3,
        per_ray (2 + 5) / 2 = 3.5; with ray weights [1, 3]: points (1+3+15)/5 = 3.8,
        per_ray (2 + 15) / 4 = 4.25.
    """
    selected = torch.where(mask, values, torch.zeros_like(values))
    counts = mask.sum(dim=-1).to(values.dtype)
    if reduction == "points":
        sums, shares = selected.sum(dim=-1), counts
    elif reduction == "per_ray":
        sums, shares = selected.sum(dim=-1) / counts.clamp(min=1.0), (counts > 0).to(values.dtype)
    else:
        raise ValueError(f"reduction must be 'per_ray' or 'points', got '{reduction}'")
    if ray_weights is not None:
        weight = ray_weights.to(values.dtype)
        sums, shares = sums * weight, shares * weight
    return ratio_or_zero(sums.sum(), shares.sum())


def sdf_loss_terms(
    sdf: torch.Tensor,
    z_vals: torch.Tensor,
    depth: torch.Tensor,
    truncation: float,
    config: LossConfig,
    ray_mask: torch.Tensor | None = None,
    ray_weights: torch.Tensor | None = None,
) -> SdfTerms:
    """Free-space, truncation-middle and truncation-tail losses of the sampled TSDF.

    front = z < D - T: (s - 1)^2; middle = |z - D| < f T and tail = f T <= |z - D| <= T:
    (z + s T - D)^2, f = ``config.middle_fraction``; with ``config.single_band`` (ablation
    g) middle is the whole band |z - D| <= T and tail is empty. Each term is reduced by
    :func:`masked_mean` with ``config.reduction``; an empty set gives 0.

    Args:
        sdf: (N, S) predicted TSDF, units of T.
        z_vals: (N, S) sample depths, metres.
        depth: (N,) measured depth D, metres.
        truncation: T, metres.
        ray_mask: optional (N,) bool; rays where it is False are left out.
        ray_weights: optional (N,) weights of the rays in each mean (:func:`masked_mean`).

    Returns:
        SdfTerms(free_space, trunc_middle, trunc_tail), scalar tensors.
    """
    target = depth.unsqueeze(-1)
    gap = z_vals - target
    distance = gap.abs()
    front = gap < -truncation
    band = distance <= truncation
    if config.single_band:
        middle, tail = band, torch.zeros_like(band)
    else:
        middle = distance < config.middle_fraction * truncation
        tail = band & ~middle
    if ray_mask is not None:
        keep = ray_mask.unsqueeze(-1)
        front, middle, tail = front & keep, middle & keep, tail & keep
    free = (sdf - 1.0).square()
    surface = (gap + sdf * truncation).square()
    return SdfTerms(
        free_space=masked_mean(free, front, config.reduction, ray_weights),
        trunc_middle=masked_mean(surface, middle, config.reduction, ray_weights),
        trunc_tail=masked_mean(surface, tail, config.reduction, ray_weights),
    )


def inlier_rays(
    residual: torch.Tensor, factor: float, valid: torch.Tensor | None = None
) -> torch.Tensor:
    """(N,) bool: rays whose |depth residual| is at most ``factor`` times the batch median.

    The release's tracker drops the others (factor 10). The median runs over the
    ``valid`` rays only (all when None), without gradient, and is torch's lower middle
    value for an even count. Invalid rays are never inliers.
    """
    error = residual.detach().abs()
    if valid is None:
        return error <= factor * error.median()
    median = torch.where(valid, error, torch.nan).nanmedian()
    return valid & (error <= factor * median)


def compute_losses(
    output: RenderOutput,
    rays: RayBatch,
    weights: LossWeights,
    truncation: float,
    config: LossConfig,
    outlier_factor: float | None = None,
    ray_weights: torch.Tensor | None = None,
) -> LossTerms:
    """All five loss terms and their weighted sum, for tracking and mapping alike.

    depth = mean over rays of (D_hat - D)^2; colour = mean over rays AND channels of
    (C_hat - C)^2 (the release's reduction, for which the published weights were tuned:
    a third of the per-ray squared norm ||C_hat - C||^2), 0 when ``output.rgb`` is None;
    the TSDF terms from :func:`sdf_loss_terms`. With ``outlier_factor`` (tracking,
    release: 10) rays with |D_hat - D| > outlier_factor * median are dropped from every
    term. With ``ray_weights`` w_r (mapping's depth-noise model,
    :func:`depth_noise_weights`) the depth term is sum w_r (D_hat - D)^2 / sum w_r over
    the kept rays and the TSDF terms are weighted means likewise; the colour term stays
    unweighted (the weights model the depth's noise, not the colour's).
    total = lambda_fs fs + lambda_Tm Tm + lambda_Tt Tt + lambda_d d + lambda_c c.

    Args:
        output: the rendering of ``rays`` (N rays, S samples).
        rays: the rays with their measured depth and colour; rays with depth <= 0 are left out.
        weights: the five lambdas.
        truncation: T, metres.
        outlier_factor: None (mapping) or the rejection factor (tracking).
        ray_weights: None (plain means) or (N,) non-negative weights per ray.

    Returns:
        LossTerms (scalar tensors).
    """
    residual = output.depth - rays.depth
    keep = rays.depth > 0
    if outlier_factor is not None:
        keep = inlier_rays(residual, outlier_factor, keep)
    count = keep.sum().to(residual.dtype)
    zero = torch.zeros((), dtype=residual.dtype, device=residual.device)
    share = keep.to(residual.dtype)
    if ray_weights is not None:
        share = torch.where(keep, ray_weights.to(residual.dtype), zero)
    depth_term = ratio_or_zero(
        torch.where(keep, share * residual.square(), zero).sum(), share.sum()
    )
    if output.rgb is None:
        colour_term = zero
    else:
        colour_error = (output.rgb - rays.rgb).square().mean(dim=-1)
        colour_term = ratio_or_zero(torch.where(keep, colour_error, zero).sum(), count)
    sdf_terms = sdf_loss_terms(
        output.sdf, output.z_vals, rays.depth, truncation, config, keep, ray_weights
    )
    total = (
        weights.free_space * sdf_terms.free_space
        + weights.trunc_middle * sdf_terms.trunc_middle
        + weights.trunc_tail * sdf_terms.trunc_tail
        + weights.depth * depth_term
        + weights.colour * colour_term
    )
    return LossTerms(
        free_space=sdf_terms.free_space,
        trunc_middle=sdf_terms.trunc_middle,
        trunc_tail=sdf_terms.trunc_tail,
        depth=depth_term,
        colour=colour_term,
        total=total,
    )
