"""Rigid-body pose maths on SE(3), batched torch functions.

Conventions: a pose T is a camera-to-world 4x4 matrix [[R, t], [0, 1]] with OpenCV camera
axes; translations in metres, angles in radians. Quaternions are scalar-last (x, y, z, w).
A twist xi = (v, omega) (translation part first) maps to a pose by ``se3_exp``.

Every function is pure, works over leading batch dimensions ``...``, keeps the dtype and
device of its input (float32 or float64) and is differentiable unless its docstring says
otherwise; the series/branch choices that keep them exact near 0 and pi are described in
``eslam.geometry.rotation``, whose public functions this module re-exports so that all
pose maths can be imported from here.
"""

from __future__ import annotations

import torch

from eslam.geometry.rotation import (
    _SERIES_ANGLE_SQ,
    _eye_like,
    _hat,
    _rotation_coefficients,
    matrix_to_quaternion,
    orthonormalize_rotation,
    quaternion_to_matrix,
    renormalise_rotation,
    rotation_angle,
    so3_exp,
    so3_log,
)

__all__ = [
    "compose",
    "extrapolate_constant_velocity",
    "interpolate_pose",
    "invert",
    "matrix_to_quaternion",
    "orthonormalize_rotation",
    "pose_distance",
    "pose_from_quaternion_translation",
    "quaternion_to_matrix",
    "quaternion_translation_from_pose",
    "renormalise_rotation",
    "rotation_angle",
    "se3_exp",
    "se3_log",
    "so3_exp",
    "so3_log",
]


def _make_pose(rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """[[R, t], [0, 1]] from (..., 3, 3) and (..., 3), broadcasting their batch dims."""
    batch = torch.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    rotation = rotation.expand(*batch, 3, 3)
    translation = translation.expand(*batch, 3)
    top = torch.cat((rotation, translation.unsqueeze(-1)), dim=-1)
    bottom = torch.zeros(4, dtype=top.dtype, device=top.device)
    bottom[3] = 1.0
    return torch.cat((top, bottom.expand(*batch, 1, 4)), dim=-2)


def _inverse_jacobian_coefficient(theta_sq: torch.Tensor) -> torch.Tensor:
    """D = 1 / t^2 - cot(t / 2) / (2 t) of V^-1 = I - K / 2 + D K^2, as a function of t^2.

    Equal to (1 - t sin t / (2 (1 - cos t))) / t^2; this form stays finite at t = pi.
    """
    small = theta_sq < _SERIES_ANGLE_SQ
    t2 = theta_sq
    theta = torch.sqrt(torch.where(small, torch.ones_like(t2), t2))
    half = 0.5 * theta
    d_exact = 1 / (theta * theta) - torch.cos(half) / (2 * theta * torch.sin(half))
    d_series = (1 + t2 / 60 * (1 + t2 / 42 * (1 + t2 / 40 * (1 + t2 * 5 / 198)))) / 12
    return torch.where(small, d_series, d_exact)


def se3_exp(xi: torch.Tensor) -> torch.Tensor:
    """Pose of a twist xi = (v, omega).

    T = [[R, V v], [0, 1]] with R = so3_exp(omega) and the left Jacobian
    V = I + B K + C K^2, K = hat(omega), B = (1 - cos(theta)) / theta^2,
    C = (theta - sin(theta)) / theta^3 (series below theta = 0.1).

    Args:
        xi: (..., 6) twist, translation part v (metres) first, rotation part omega (radians).

    Returns:
        (..., 4, 4) pose.
    """
    v, omega = xi[..., :3], xi[..., 3:]
    k = _hat(omega)
    k2 = k @ k
    a, b, c = _rotation_coefficients((omega * omega).sum(-1))
    eye = _eye_like(xi, 3)
    rotation = eye + a[..., None, None] * k + b[..., None, None] * k2
    jacobian = eye + b[..., None, None] * k + c[..., None, None] * k2
    return _make_pose(rotation, (jacobian @ v.unsqueeze(-1)).squeeze(-1))


def se3_log(pose: torch.Tensor) -> torch.Tensor:
    """Twist xi = (v, omega) of a pose; inverse of ``se3_exp`` for angles in [0, pi].

    omega = so3_log(R), v = V^-1 t with V^-1 = I - K / 2 + D K^2, K = hat(omega),
    D = 1 / theta^2 - cot(theta / 2) / (2 theta) (series 1/12 + theta^2/720 + ... near 0;
    finite at pi where cot(pi/2) = 0).

    Args:
        pose: (..., 4, 4) rigid transform.

    Returns:
        (..., 6) twist, translation part first.
    """
    omega = so3_log(pose[..., :3, :3])
    t = pose[..., :3, 3]
    k = _hat(omega)
    d = _inverse_jacobian_coefficient((omega * omega).sum(-1))
    v_inverse = _eye_like(pose, 3) - 0.5 * k + d[..., None, None] * (k @ k)
    v = (v_inverse @ t.unsqueeze(-1)).squeeze(-1)
    return torch.cat((v, omega), dim=-1)


def compose(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """a @ b for (..., 4, 4) poses (apply b, then a); batch dims broadcast."""
    return a @ b


def invert(pose: torch.Tensor) -> torch.Tensor:
    """Rigid inverse [[R^T, -R^T t], [0, 1]] of (..., 4, 4) poses (no general inverse)."""
    rotation_t = pose[..., :3, :3].transpose(-1, -2)
    translation = -(rotation_t @ pose[..., :3, 3:]).squeeze(-1)
    return _make_pose(rotation_t, translation)


def pose_from_quaternion_translation(q: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """[[quaternion_to_matrix(q), t], [0, 1]].

    Args:
        q: (..., 4) quaternion (x, y, z, w), normalised inside.
        t: (..., 3) translation, metres; batch dims broadcast with those of q.

    Returns:
        (..., 4, 4) pose.
    """
    return _make_pose(quaternion_to_matrix(q), t)


def quaternion_translation_from_pose(pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Split (..., 4, 4) poses into a (..., 4) quaternion (x, y, z, w; w >= 0) and (..., 3) t."""
    return matrix_to_quaternion(pose[..., :3, :3]), pose[..., :3, 3]


def interpolate_pose(
    pose0: torch.Tensor, pose1: torch.Tensor, s: float | torch.Tensor
) -> torch.Tensor:
    """Geodesic interpolation on SE(3): T0 @ exp(s * log(T0^-1 @ T1)).

    s = 0 gives T0, s = 1 gives T1, s outside [0, 1] extrapolates along the same
    constant twist. The relative rotation must be below pi for the path to be unique.

    Args:
        pose0: (..., 4, 4) pose T0.
        pose1: (..., 4, 4) pose T1.
        s: a float, or a tensor broadcastable to the batch dims ``...``.

    Returns:
        (..., 4, 4) interpolated pose.
    """
    xi = se3_log(invert(pose0) @ pose1)
    s = torch.as_tensor(s, dtype=xi.dtype, device=xi.device)
    return pose0 @ se3_exp(s.unsqueeze(-1) * xi)


def extrapolate_constant_velocity(pose_prev: torch.Tensor, pose_curr: torch.Tensor) -> torch.Tensor:
    """Constant-velocity guess of the next pose: T_curr @ (T_prev^-1 @ T_curr).

    This is the tracker's initialisation of a new frame: the last relative motion
    (in the camera frame) is applied once more. ESLAM's release extrapolates the raw
    quaternion + translation 7-vector linearly; we extrapolate on SE(3), which keeps
    the result a rigid transform and is exact for a constant-twist trajectory. The
    product R_k R_(k-1)^T R_k multiplies an orthonormality error of its inputs by about
    2.4, and a tracker that corrects the prediction by exp(xi) T (the SDF tracker)
    passes it on: float32 rounding reached 1e-2 after ~15 frames and overflowed after
    ~25. So the rotation is pulled back onto SO(3) (:func:`renormalise_rotation`).

    Args:
        pose_prev: (..., 4, 4) camera-to-world pose of frame k - 1.
        pose_curr: (..., 4, 4) camera-to-world pose of frame k.

    Returns:
        (..., 4, 4) predicted pose of frame k + 1.
    """
    predicted = pose_curr @ (invert(pose_prev) @ pose_curr)
    return _make_pose(renormalise_rotation(predicted[..., :3, :3]), predicted[..., :3, 3])


def pose_distance(pose_a: torch.Tensor, pose_b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Translation distance (metres) and relative rotation angle (radians) of two poses.

    Args:
        pose_a: (..., 4, 4) pose.
        pose_b: (..., 4, 4) pose; batch dims broadcast.

    Returns:
        |t_a - t_b| (...) and rotation_angle(R_a^T R_b) (...).
    """
    translation = torch.linalg.vector_norm(pose_a[..., :3, 3] - pose_b[..., :3, 3], dim=-1)
    relative = pose_a[..., :3, :3].transpose(-1, -2) @ pose_b[..., :3, :3]
    return translation, rotation_angle(relative)
