"""The SDF tracker's maths: residuals, robust weights, Jacobians and the normal equations
of a frame's points at a pose, and how well they pin the pose down.

Point-to-implicit tracking (Bylow et al. 2013; KinectFusion's successors; PIN-SLAM):
a frame's valid depth pixels are back-projected to camera points q_i, moved into the
world by the pose T, and the map's TSDF is queried once per point, with no rendering.
A correct pose puts every measured point on the surface, so the residual is

    r_i(T) = T_tr * s(T q_i)        (metres; s is the TSDF in units of T_tr)

and the pose minimises sum_i w_i r_i^2 with robust weights w_i (Huber or
Geman-McClure on r_i; points whose |s| reaches ``max_sdf`` sit where the truncated
field is flat and carry no information, and points outside the scene bound read its
border: both get weight 0). The pose is updated on the left, T <- exp(xi) T with
xi = (v, omega) (:func:`~eslam.geometry.pose.se3_exp`); to first order a world point
p = T q moves by v + omega x p, so the Jacobian row of point i is

    J_i = T_tr * [g_i^T, (p_i x g_i)^T],    g_i = grad_p s(p_i)  (autograd through the field)

and each Levenberg-Marquardt step solves (J^T W J + lambda diag(J^T W J)) xi = -J^T W r,
accepting it when the robust cost drops (lambda shrinks) and rejecting it otherwise
(lambda grows). The points are a fixed, seeded subset of the frame's valid pixels,
used coarse to fine (the first ``levels[0]`` points, then more).

**Depth noise** (``noise_reference_depth`` z0; off by default). Depth from structured
light or stereo is noisier far away, sigma(z) proportional to z^2 (Khoshelham and
Elberink 2012), so with z0 set each residual and its Jacobian row are divided by
sigma(z_i) / sigma(z0) = (z_i / z0)^2 before the robust weights: weighted least squares
with w_i ~ z_i^-4, near points counting more (as DVO-SLAM and ElasticFusion weight their
depth terms).

**Colour term** (``colour_weight`` lambda > 0; off by default). Dense photometric
alignment (Steinbruecker, Sturm and Cremers 2011; Kerl, Sturm and Cremers 2013), here
against the map's decoded colour at the point as in Bylow et al.'s colour extension of
point-to-TSDF tracking: each point also has the three residuals

    r^c_ik(T) = lambda * (c_k(T q_i) - C_ik),   k = R, G, B

with C_i the frame's colour at the point's pixel and c the field's decoded colour, both
in [0, 1]. lambda is in metres per unit colour, so the colour residual is compared with
the SDF residual in metres: lambda = 0.05 makes a colour error of 0.1 weigh like a 5 mm
SDF error (choose it near sigma_sdf / sigma_colour, the ratio of the two noise levels).
Its robust loss is the SDF term's kind with scale lambda * ``colour_robust_scale`` (so
the weights are those of the unscaled residual with scale ``colour_robust_scale``), it
shares the SDF term's validity (weight 0 outside the band or the bound; an invalid point
counts rho(lambda) per channel in the cost) and its Jacobian rows are

    J^c_ik = lambda * [h_ik^T, (p_i x h_ik)^T],   h_ik = grad_p c_k(p_i),

stacked into the same normal equations: H = J^T W J + sum_k J^cT_k W^c_k J^c_k, and
likewise the gradient. Cost: the field is queried with colour, and autograd runs four
backward passes (SDF and three channels) instead of one (the cost: docs/benchmarks.md,
"What we tried and ruled out"). With ``colour_when: degenerate`` a frame starts geometric and
adds the colour term only if its first linearisation (at the guess, coarsest level)
has a direction below ``degeneracy`` (:func:`constrained_directions`): the views whose
geometry cannot pin the pose get the texture, the others the geometric tracker as is.

The solver that uses these systems is :mod:`eslam.slam.tracking.sdf`.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from eslam.config import SdfTrackerConfig
from eslam.losses import depth_noise_scale
from eslam.render.renderer import SceneFieldLike


def robust_weights(residual: torch.Tensor, scale: float, kind: str) -> torch.Tensor:
    """IRLS weights of residuals (metres) for the robust loss ``kind`` with ``scale`` c.

    Huber: w = 1 for |r| <= c, else c / |r|. Geman-McClure rho = r^2 / (r^2 + c^2):
    w = c^4 / (r^2 + c^2)^2 (1 at r = 0, falling off as r^-4).
    """
    if kind == "huber":
        magnitude = residual.abs()
        return torch.where(magnitude <= scale, torch.ones_like(residual), scale / magnitude)
    if kind == "geman_mcclure":
        return scale**4 / (residual.square() + scale**2).square()
    raise ValueError(f"robust must be 'huber' or 'geman_mcclure', got '{kind}'")


def robust_cost(residual: torch.Tensor, scale: float, kind: str) -> torch.Tensor:
    """(N,) robust loss rho(r) of residuals (metres) whose IRLS weights are
    :func:`robust_weights`: Huber r^2 / 2 (|r| <= c), c |r| - c^2 / 2 (beyond);
    Geman-McClure c^2 r^2 / (2 (r^2 + c^2))."""
    if kind == "huber":
        magnitude = residual.abs()
        return torch.where(
            magnitude <= scale, 0.5 * residual.square(), scale * magnitude - 0.5 * scale**2
        )
    if kind == "geman_mcclure":
        squared = residual.square()
        return 0.5 * scale**2 * squared / (squared + scale**2)
    raise ValueError(f"robust must be 'huber' or 'geman_mcclure', got '{kind}'")


def inside_bound(points: torch.Tensor, bound: torch.Tensor) -> torch.Tensor:
    """(N,) bool: points within the (3, 2) scene box."""
    return ((points >= bound[:, 0]) & (points <= bound[:, 1])).all(dim=-1)


@dataclass(frozen=True, eq=False)
class Linearisation:
    """Residuals, weights and the Gauss-Newton system of a set of points at one pose.

    Attributes:
        residual: (N,) r_i, metres.
        weight: (N,) robust weight times validity (0 for saturated or outside points).
        cost: 0-d sum_i rho(r_i), an invalid point counting as rho(T) (as far as it can
            be): so a step that brings points into the band lowers the cost; plus the
            colour term's robust cost when it is on.
        hessian: (6, 6) J^T W J (float64), both terms.
        gradient: (6,) J^T W r (float64), both terms.
        valid: (N,) bool, points inside the bound and the band.
        centre: (3,) float64 weighted centroid of the points (for :func:`constrained_directions`).
    """

    residual: torch.Tensor
    weight: torch.Tensor
    cost: torch.Tensor
    hessian: torch.Tensor
    gradient: torch.Tensor
    valid: torch.Tensor
    centre: torch.Tensor


def twist_jacobian(points: torch.Tensor, gradient: torch.Tensor) -> torch.Tensor:
    """(N, 6) rows [g^T, (p x g)^T]: the derivative of a scalar field f at the points p
    with respect to a left twist xi = (v, omega), since p moves by v + omega x p and
    d f = g . (v + omega x p) = g . v + (p x g) . omega, with g = grad_p f (N, 3)."""
    return torch.cat((gradient, torch.cross(points, gradient, dim=-1)), dim=-1)


def field_derivatives(
    field: SceneFieldLike, points: torch.Tensor, with_rgb: bool
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """TSDF s (N,), its spatial gradient (N, 3), and with ``with_rgb`` the decoded colour
    (N, 3) and its spatial Jacobian (N, 3, 3), [i, k] = grad_p c_k(p_i), by autograd.

    One field query; one backward pass for s and one per colour channel (a point's
    outputs depend only on that point, so the gradient of a channel's sum is the
    per-point gradient). The field's parameters must not require gradients.
    """
    with torch.enable_grad():
        points = points.detach().requires_grad_(True)
        output = field.query(points, with_rgb=with_rgb)
        outputs = [output.sdf]
        if with_rgb:
            if output.rgb is None:
                raise ValueError("the field decodes no colour: set tracking.sdf.colour_weight: 0")
            outputs += list(output.rgb.unbind(dim=-1))
        gradients = [
            torch.autograd.grad(value.sum(), points, retain_graph=index < len(outputs) - 1)[0]
            for index, value in enumerate(outputs)
        ]
    if not with_rgb:
        return output.sdf.detach(), gradients[0], None, None
    assert output.rgb is not None
    return output.sdf.detach(), gradients[0], output.rgb.detach(), torch.stack(gradients[1:], 1)


def linearise(
    field: SceneFieldLike,
    points_cam: torch.Tensor,
    pose: torch.Tensor,
    config: SdfTrackerConfig,
    colours: torch.Tensor | None = None,
) -> Linearisation:
    """Residuals r_i = T s(T q_i), their robust weights and J^T W J, J^T W r (module doc);
    with ``config.noise_reference_depth`` z0 set, r_i and J_i divided by (z_i / z0)^2
    first (:func:`depth_noise_scale`; ``residual`` stays in metres); with
    ``config.colour_weight`` > 0 also the colour term against ``colours`` (N, 3),
    the frame's observed colour at the points' pixels in [0, 1].

    The field's parameters must not require gradients (only the points do).
    """
    truncation = field.truncation
    with_colour = config.colour_weight > 0
    if with_colour and colours is None:
        raise ValueError("colour_weight > 0 needs the points' observed colours")
    points = (points_cam @ pose[:3, :3].T + pose[:3, 3]).detach()
    sdf, gradient, rgb, rgb_gradient = field_derivatives(field, points, with_colour)
    residual = truncation * sdf
    noise = depth_noise_scale(points_cam[:, 2], config.noise_reference_depth)
    normalised = residual / noise
    valid = (sdf.abs() < config.max_sdf) & inside_bound(points, field.bound)
    weight = robust_weights(normalised, config.robust_scale, config.robust) * valid
    far = torch.full_like(residual, truncation)
    cost = robust_cost(
        torch.where(valid, residual, far) / noise, config.robust_scale, config.robust
    )
    jacobian = (truncation * twist_jacobian(points, gradient) / noise[:, None]).double()
    weighted = jacobian * weight.double()[:, None]
    hessian = weighted.T @ jacobian
    gradient_xi = weighted.T @ normalised.double()
    cost = cost.sum()
    if with_colour:
        assert colours is not None and rgb is not None and rgb_gradient is not None
        scale = config.colour_weight
        colour_scale = scale * config.colour_robust_scale
        colour_residual = scale * (rgb - colours)  # (N, 3)
        colour_weight = robust_weights(colour_residual, colour_scale, config.robust)
        colour_weight = colour_weight * valid[:, None]
        worst = torch.full_like(colour_residual, scale)
        colour_cost = robust_cost(
            torch.where(valid[:, None], colour_residual, worst), colour_scale, config.robust
        )
        cost = cost + colour_cost.sum()
        for channel in range(3):
            rows = (scale * twist_jacobian(points, rgb_gradient[:, channel])).double()
            rows_weighted = rows * colour_weight[:, channel].double()[:, None]
            hessian = hessian + rows_weighted.T @ rows
            gradient_xi = gradient_xi + rows_weighted.T @ colour_residual[:, channel].double()
    total = weight.double().sum().clamp_min(1e-12)
    return Linearisation(
        residual=residual,
        weight=weight,
        cost=cost,
        hessian=hessian,
        gradient=gradient_xi,
        valid=valid,
        centre=(weight.double()[:, None] * points.double()).sum(dim=0) / total,
    )


def cross_matrix(vector: torch.Tensor) -> torch.Tensor:
    """(3, 3) [a]_x with [a]_x b = a x b."""
    x, y, z = vector.unbind()
    zero = torch.zeros_like(x)
    return torch.stack(
        (torch.stack((zero, -z, y)), torch.stack((z, zero, -x)), torch.stack((-y, x, zero)))
    )


def centred_tangent(centre: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(A, A^-1) with xi_c = A xi: the tangent centred on ``centre`` c, where a point moves
    by v_c + omega x (p - c), v_c = v + omega x c; A = [[I, -[c]_x], [0, I]] (float64)."""
    identity = torch.eye(6, dtype=torch.float64, device=centre.device)
    to_centred, from_centred = identity.clone(), identity.clone()
    to_centred[:3, 3:] = -cross_matrix(centre)
    from_centred[:3, 3:] = cross_matrix(centre)
    return to_centred, from_centred


def normalised_information(system: Linearisation) -> tuple[torch.Tensor, torch.Tensor]:
    """Eigenvalues (ascending) and eigenvectors of the information per point,
    H_c / sum_i w_i with H_c = A^-T H A^-1 in the centred tangent (:func:`centred_tangent`),
    so translations and rotations do not mix through the world origin. About 1 along a
    direction every point's normal sees; rotations count with their lever arm (metres)."""
    _, from_centred = centred_tangent(system.centre)
    information = from_centred.T @ system.hessian @ from_centred
    information = information / system.weight.double().sum().clamp_min(1e-12)
    return torch.linalg.eigh(information)


def constrained_directions(
    system: Linearisation, threshold: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Projector onto the pose directions the points constrain, and how many are not.

    Degeneracy test of Zhang, Kaess and Singh (ICRA 2016, "On degeneracy of
    optimization-based state estimation problems"): an eigenvector of the information
    matrix whose eigenvalue is small is a direction the data cannot see (sliding along a
    plane or a corridor; turning about a cylinder's axis), and a step along it only
    follows noise, so the step is projected onto the well-constrained eigenvectors and the
    guess is kept along the others. Eigenvalues of :func:`normalised_information` below
    ``threshold`` are degenerate; the projector in the solver's tangent is A^-1 P_c A.

    No host read: the projector is V diag(m) V^T with m_k = 1 for a kept eigenvector,
    selected with ``torch.where``.

    Returns:
        (6, 6) float64 projector (the identity when nothing is degenerate or
        ``threshold`` is 0) and the number of degenerate directions (0-d int64 tensor).
    """
    identity = torch.eye(6, dtype=torch.float64, device=system.hessian.device)
    if threshold <= 0:
        return identity, torch.zeros((), dtype=torch.int64, device=identity.device)
    eigenvalues, eigenvectors = normalised_information(system)
    kept = (eigenvalues >= threshold).double()
    degenerate = 6 - kept.sum().long()
    to_centred, from_centred = centred_tangent(system.centre)
    projector = from_centred @ (eigenvectors * kept) @ eigenvectors.T @ to_centred
    return torch.where(degenerate == 0, identity, projector), degenerate


def information_figures(system: Linearisation, threshold: float) -> tuple[float, int | None]:
    """(smallest eigenvalue of :func:`normalised_information`, directions below
    ``threshold``) at a linearisation: how well its points pin the pose down (reads the
    device). The count is None when ``threshold`` is 0 (no test); with no weighted point
    the eigenvalue is NaN and all 6 directions count."""
    counted = threshold > 0
    if not bool(system.weight.sum() > 0):
        return float("nan"), 6 if counted else None
    eigenvalues, _ = normalised_information(system)
    degenerate = int((eigenvalues < threshold).sum()) if counted else None
    return float(eigenvalues[0]), degenerate


def damped_step(system: Linearisation, damping: torch.Tensor) -> torch.Tensor:
    """(6,) xi solving (H + lambda diag(H) + eps I) xi = -g (float64; never raises)."""
    hessian = system.hessian
    diagonal = torch.diagonal(hessian)
    regular = 1e-9 * (1.0 + diagonal.abs().max())
    damped = hessian + torch.diag(damping * diagonal + regular)
    step, _ = torch.linalg.solve_ex(damped, -system.gradient[:, None])
    return step[:, 0]
