"""Rotation maths on SO(3): quaternions, rotation vectors, batched torch functions.

Quaternions are scalar-last (x, y, z, w), as in scipy and the TUM trajectory format; a
rotation vector omega = angle * unit_axis (radians) maps to a rotation by ``so3_exp``.

Every function is pure, works over leading batch dimensions ``...``, keeps the dtype and
device of its input (float32 or float64) and is differentiable unless its docstring says
otherwise. Below theta = 0.1 the exp/log coefficients use Taylor series to theta^8 (exact
to float64 rounding, where the closed forms would cancel); ``so3_log`` reads the angle
with atan2 and, past 90 degrees, the axis from the symmetric part of R, so every function
is accurate near 0 and near pi. ``eslam.geometry.pose`` builds SE(3) on top and
re-exports these names.
"""

from __future__ import annotations

import torch

_SERIES_ANGLE_SQ = 1e-2  # theta^2 below which exp/log coefficients use series (theta < 0.1)
_LOG_SERIES_SIN_SQ = 1e-4  # sin(theta)^2 below which so3_log uses the asin(x)/x series


def _hat(omega: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 3, 3) skew matrix K with K @ x = omega x x."""
    x, y, z = omega.unbind(-1)
    zero = torch.zeros_like(x)
    rows = (
        torch.stack((zero, -z, y), dim=-1),
        torch.stack((z, zero, -x), dim=-1),
        torch.stack((-y, x, zero), dim=-1),
    )
    return torch.stack(rows, dim=-2)


def _vee_antisymmetric(m: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) -> (..., 3) vector of the antisymmetric part: vee((M - M^T) / 2)."""
    return 0.5 * torch.stack(
        (m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]),
        dim=-1,
    )


def _eye_like(m: torch.Tensor, n: int) -> torch.Tensor:
    return torch.eye(n, dtype=m.dtype, device=m.device)


def _rotation_coefficients(theta_sq: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """A = sin t / t, B = (1 - cos t) / t^2, C = (t - sin t) / t^3 as functions of t^2.

    B is evaluated as 2 sin^2(t/2) / t^2, free of the cancellation in 1 - cos t.
    """
    small = theta_sq < _SERIES_ANGLE_SQ
    t2 = theta_sq
    theta = torch.sqrt(torch.where(small, torch.ones_like(t2), t2))
    half_sin = torch.sin(0.5 * theta)
    a_exact = torch.sin(theta) / theta
    b_exact = 2.0 * half_sin * half_sin / (theta * theta)
    c_exact = (theta - torch.sin(theta)) / (theta * theta * theta)
    a_series = 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42 * (1 - t2 / 72)))
    b_series = 0.5 * (1 - t2 / 12 * (1 - t2 / 30 * (1 - t2 / 56 * (1 - t2 / 90))))
    c_series = (1 - t2 / 20 * (1 - t2 / 42 * (1 - t2 / 72 * (1 - t2 / 110)))) / 6
    return (
        torch.where(small, a_series, a_exact),
        torch.where(small, b_series, b_exact),
        torch.where(small, c_series, c_exact),
    )


def quaternion_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrix of a scalar-last quaternion, normalising it first.

    With s = 2 / |q|^2 (so q need not be unit; q = 0 is undefined):
    R = I + s * [[-(y^2+z^2), xy-zw, xz+yw], [xy+zw, -(x^2+z^2), yz-xw],
    [xz-yw, yz+xw, -(x^2+y^2)]]. Differentiable (tracking optimises q through it).

    Args:
        q: (..., 4) quaternion (x, y, z, w).

    Returns:
        (..., 3, 3) rotation matrix.
    """
    x, y, z, w = q.unbind(-1)
    s = 2.0 / (q * q).sum(-1)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    xw, yw, zw = s * x * w, s * y * w, s * z * w
    rows = (
        torch.stack((1 - yy - zz, xy - zw, xz + yw), dim=-1),
        torch.stack((xy + zw, 1 - xx - zz, yz - xw), dim=-1),
        torch.stack((xz - yw, yz + xw, 1 - xx - yy), dim=-1),
    )
    return torch.stack(rows, dim=-2)


def matrix_to_quaternion(rotation: torch.Tensor) -> torch.Tensor:
    """Unit scalar-last quaternion of a rotation matrix, with w >= 0.

    Shepperd's method without branches: the four candidates
    4w q = (R21-R12, R02-R20, R10-R01, 1+tr), 4x q = (1+R00-R11-R22, R01+R10, R02+R20,
    R21-R12), 4y q = (...), 4z q = (...) are all formed, the one whose pivot 4 q_i^2 is
    largest (best conditioned) is kept and normalised, then the sign is set so w >= 0.

    Args:
        rotation: (..., 3, 3) rotation matrix.

    Returns:
        (..., 4) quaternion (x, y, z, w).
    """
    r = rotation
    r00, r01, r02 = r[..., 0, 0], r[..., 0, 1], r[..., 0, 2]
    r10, r11, r12 = r[..., 1, 0], r[..., 1, 1], r[..., 1, 2]
    r20, r21, r22 = r[..., 2, 0], r[..., 2, 1], r[..., 2, 2]
    pivots = torch.stack(
        (1 + r00 - r11 - r22, 1 - r00 + r11 - r22, 1 - r00 - r11 + r22, 1 + r00 + r11 + r22),
        dim=-1,
    )
    candidates = torch.stack(
        (
            torch.stack((pivots[..., 0], r01 + r10, r02 + r20, r21 - r12), dim=-1),
            torch.stack((r01 + r10, pivots[..., 1], r12 + r21, r02 - r20), dim=-1),
            torch.stack((r02 + r20, r12 + r21, pivots[..., 2], r10 - r01), dim=-1),
            torch.stack((r21 - r12, r02 - r20, r10 - r01, pivots[..., 3]), dim=-1),
        ),
        dim=-2,
    )
    best = pivots.argmax(dim=-1, keepdim=True)
    index = best.unsqueeze(-1).expand(*best.shape[:-1], 1, 4)
    q = torch.gather(candidates, -2, index).squeeze(-2)
    q = q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)
    return torch.where(q[..., 3:] < 0, -q, q)


def so3_exp(omega: torch.Tensor) -> torch.Tensor:
    """Rotation matrix of a rotation vector (Rodrigues).

    R = I + A K + B K^2 with K = hat(omega), theta = |omega|, A = sin(theta) / theta,
    B = (1 - cos(theta)) / theta^2 (series below theta = 0.1).

    Args:
        omega: (..., 3) rotation vector, radians.

    Returns:
        (..., 3, 3) rotation matrix.
    """
    k = _hat(omega)
    a, b, _ = _rotation_coefficients((omega * omega).sum(-1))
    return _eye_like(omega, 3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def so3_log(rotation: torch.Tensor) -> torch.Tensor:
    """Rotation vector of a rotation matrix, angle in [0, pi].

    With a = vee(R - R^T) / 2 = sin(theta) n and c = (tr R - 1) / 2 = cos(theta),
    theta = atan2(|a|, c) (accurate everywhere, unlike acos). For theta <= pi/2,
    omega = theta / sin(theta) * a (series in |a|^2 near 0). Past pi/2 the axis comes from
    the symmetric part, n n^T = ((R + R^T) / 2 - c I) / (1 - c): the column with the largest
    diagonal gives n up to sign, and the sign is that of n . a. At exactly pi both signs are
    valid logarithms.

    Args:
        rotation: (..., 3, 3) rotation matrix.

    Returns:
        (..., 3) rotation vector omega = theta * n, radians.
    """
    r = rotation
    a = _vee_antisymmetric(r)
    a_sq = (a * a).sum(-1)
    c = 0.5 * (r.diagonal(dim1=-2, dim2=-1).sum(-1) - 1)
    sin_theta = torch.sqrt(a_sq.clamp_min(torch.finfo(r.dtype).tiny))
    theta = torch.atan2(sin_theta, c)

    # theta <= pi/2: omega = theta / sin(theta) * a; asin(x)/x series for small x = |a|.
    x2 = a_sq
    series = 1 + x2 / 6 * (1 + x2 * 9 / 20 * (1 + x2 * 25 / 42 * (1 + x2 * 49 / 72)))
    small = x2 < _LOG_SERIES_SIN_SQ
    ratio = torch.where(small, series, theta / torch.where(small, torch.ones_like(x2), sin_theta))
    omega_regular = ratio.unsqueeze(-1) * a

    # theta > pi/2: axis from the symmetric part.
    near_pi = c < 0
    one_minus_c = torch.where(near_pi, 1 - c, torch.ones_like(c))
    sym = 0.5 * (r + r.transpose(-1, -2)) - c[..., None, None] * _eye_like(r, 3)
    nnt = sym / one_minus_c[..., None, None]
    diag = nnt.diagonal(dim1=-2, dim2=-1)
    best = diag.argmax(dim=-1, keepdim=True)
    column = torch.gather(nnt, -1, best.unsqueeze(-2).expand(*nnt.shape[:-1], 1)).squeeze(-1)
    pivot = torch.gather(diag, -1, best)
    pivot = torch.where(near_pi.unsqueeze(-1), pivot.clamp_min(1e-30), torch.ones_like(pivot))
    axis = column / torch.sqrt(pivot)
    sign = torch.where((axis * a).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(r.dtype)
    omega_pi = sign * axis * theta.unsqueeze(-1)

    return torch.where(near_pi.unsqueeze(-1), omega_pi, omega_regular)


def orthonormalize_rotation(rotation: torch.Tensor) -> torch.Tensor:
    """Nearest rotation matrix (Frobenius norm), e.g. for 7-Scenes poses (orthonormal ~4e-4).

    R' = U diag(1, 1, d) V^T with U S V^T = svd(R), d = det(U V^T) = +-1, so det R' = +1.
    Meant for cleaning input data: gradients through the SVD are unreliable because a
    near-rotation has (near-)equal singular values.

    Args:
        rotation: (..., 3, 3) matrix.

    Returns:
        (..., 3, 3) rotation matrix.
    """
    u, _, vh = torch.linalg.svd(rotation)
    d = torch.linalg.det(u @ vh)
    fix = torch.ones(*d.shape, 3, dtype=rotation.dtype, device=rotation.device)
    fix[..., 2] = torch.sign(d)
    return (u * fix.unsqueeze(-2)) @ vh


def renormalise_rotation(rotation: torch.Tensor, iterations: int = 2) -> torch.Tensor:
    """A near-rotation pulled back onto SO(3) without an SVD: no host sync, differentiable.

    R <- R (3 I - R^T R) / 2, ``iterations`` times: the Newton-Schulz iteration for the
    orthogonal polar factor (Bjorck and Bowie, SIAM J. Numer. Anal. 1971; Higham,
    "Functions of Matrices", SIAM 2008, chapter 8), which converges quadratically to the
    nearest rotation when ||R^T R - I|| < 1 and det R > 0 (an error e becomes about
    1.5 e^2). Meant for poses composed from other poses many times (the motion model's
    R_k R_(k-1)^T R_k multiplies an orthonormality error by about 2.4 per frame), kept
    near a rotation by calling it each time; use :func:`orthonormalize_rotation` for
    input data further off.

    Args:
        rotation: (..., 3, 3) matrix near a rotation.
        iterations: Newton-Schulz steps (2 takes an error of 1e-3 to float32 precision).

    Returns:
        (..., 3, 3) rotation matrix, same dtype and device.
    """
    eye = _eye_like(rotation, 3)
    for _ in range(iterations):
        rotation = 0.5 * rotation @ (3.0 * eye - rotation.transpose(-1, -2) @ rotation)
    return rotation


def rotation_angle(rotation: torch.Tensor) -> torch.Tensor:
    """Rotation angle in [0, pi] radians of (..., 3, 3) rotations.

    Equal to acos(clamp((tr R - 1) / 2, -1, 1)) for a rotation, but evaluated as
    atan2(|vee(R - R^T)| / 2, (tr R - 1) / 2), which keeps full precision near 0 and pi
    (acos loses half the digits there: 1e-8 rad of noise on an identical pair).
    """
    a = _vee_antisymmetric(rotation)
    c = 0.5 * (rotation.diagonal(dim1=-2, dim2=-1).sum(-1) - 1)
    return torch.atan2(torch.linalg.vector_norm(a, dim=-1), c)
