"""SO(3)/SE(3) maths against scipy, torch.linalg.matrix_exp and hand-computed values.

Rotation sets cover random angles, near-identity (1e-8..1e-4), exactly zero, and 180
degrees (pi and pi - 1e-7) about random and axis-aligned axes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import torch
from scipy.spatial.transform import Rotation

import eslam.geometry.pose as pose_module
import eslam.geometry.rotation as rotation_module
from eslam.geometry import (
    compose,
    extrapolate_constant_velocity,
    interpolate_pose,
    invert,
    matrix_to_quaternion,
    orthonormalize_rotation,
    pose_distance,
    pose_from_quaternion_translation,
    quaternion_to_matrix,
    quaternion_translation_from_pose,
    renormalise_rotation,
    rotation_angle,
    se3_exp,
    se3_log,
    so3_exp,
    so3_log,
)

TOL = 1e-9  # float64, generic
TIGHT = 1e-12  # float64, where the formula is evaluated without amplification
NEAR_PI = 1e-6  # float64, axis recovery 1e-7 below pi

AXIS_ALIGNED = np.array(
    [
        [1, 0, 0],
        [0, 1, 0],
        [0, 0, 1],
        [-1, 0, 0],
        [0, -1, 0],
        [0, 0, -1],
        [1, 1, 0],
        [0, 1, -1],
        [1, 1, 1],
    ],
    dtype=np.float64,
)
AXIS_ALIGNED /= np.linalg.norm(AXIS_ALIGNED, axis=1, keepdims=True)


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def rotvecs(kind: str, seed: int = 0) -> np.ndarray:
    """(N, 3) float64 rotation vectors of one family."""
    rng = np.random.default_rng(seed)
    if kind == "random":
        return _unit(rng, 200) * rng.uniform(0.0, math.pi * 0.999, size=(200, 1))
    if kind == "tiny":
        angles = 10.0 ** rng.uniform(-8, -4, size=(100, 1))
        return np.concatenate((_unit(rng, 100), AXIS_ALIGNED)) * np.concatenate(
            (angles, np.full((len(AXIS_ALIGNED), 1), 1e-6))
        )
    if kind == "zero":
        return np.zeros((1, 3))
    if kind == "series_edge":  # either side of the switches to series (sin^2 1e-4, angle 0.1)
        angles = np.array([[9.99e-3], [1e-2], [1.001e-2], [3e-2], [0.0999], [0.1], [0.1001]])
        return _unit(rng, len(angles)) * angles
    axes = np.concatenate((_unit(rng, 50), AXIS_ALIGNED))
    if kind == "pi":
        return axes * math.pi
    if kind == "below_pi":
        return axes * (math.pi - 1e-7)
    raise ValueError(kind)


ALL_KINDS = ["random", "tiny", "zero", "series_edge", "pi", "below_pi"]


def t64(x: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(x, dtype=torch.float64)


def random_poses(n: int, seed: int = 1, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    rot = Rotation.random(n, random_state=rng).as_matrix()
    pose = np.tile(np.eye(4), (n, 1, 1))
    pose[:, :3, :3] = rot
    pose[:, :3, 3] = rng.normal(size=(n, 3))
    return torch.as_tensor(pose, dtype=dtype)


def hat4(xi: torch.Tensor) -> torch.Tensor:
    """(..., 6) twist -> (..., 4, 4) Lie algebra matrix [[hat(omega), v], [0, 0]]."""
    v, (x, y, z) = xi[..., :3], xi[..., 3:].unbind(-1)
    out = torch.zeros(*xi.shape[:-1], 4, 4, dtype=xi.dtype)
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -z, y, -x
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = z, -y, x
    out[..., :3, 3] = v
    return out


def assert_close(actual: torch.Tensor, expected, atol: float) -> None:
    if isinstance(expected, torch.Tensor):
        expected = expected.detach().to(actual.dtype)
    else:
        expected = torch.as_tensor(np.array(expected), dtype=actual.dtype)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    err = (actual - expected).abs().max().item() if actual.numel() else 0.0
    assert err <= atol, f"max abs error {err:.3e} > {atol:.1e}"


def assert_close_up_to_sign(actual: torch.Tensor, expected: np.ndarray, atol: float) -> None:
    expected_t = t64(expected)
    err = torch.minimum(
        (actual - expected_t).abs().amax(-1), (actual + expected_t).abs().amax(-1)
    ).max()
    assert err.item() <= atol, f"max abs error up to sign {err.item():.3e} > {atol:.1e}"


# --- hand-computed values ---------------------------------------------------------------


def test_hand_values_90_degrees_about_z() -> None:
    expected = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    s = math.sin(math.pi / 4)
    q = t64([0.0, 0.0, s, s])
    assert_close(quaternion_to_matrix(q), expected, TIGHT)
    assert_close(so3_exp(t64([0.0, 0.0, math.pi / 2])), expected, TIGHT)
    assert_close(matrix_to_quaternion(t64(expected)), q.numpy(), TIGHT)
    assert_close(so3_log(t64(expected)), [0.0, 0.0, math.pi / 2], TIGHT)
    assert_close(rotation_angle(t64(expected)), math.pi / 2, TIGHT)


def test_hand_values_180_degrees_about_x() -> None:
    rot = t64(np.diag([1.0, -1.0, -1.0]))
    assert_close_up_to_sign(matrix_to_quaternion(rot), np.array([1.0, 0.0, 0.0, 0.0]), TIGHT)
    assert_close_up_to_sign(so3_log(rot), np.array([math.pi, 0.0, 0.0]), TIGHT)
    assert_close(rotation_angle(rot), math.pi, TIGHT)


def test_se3_exp_hand_value_screw() -> None:
    # Twist (v, omega) = ((1, 0, 0), (0, 0, pi/2)): V = I + (2/pi^2) K + ((pi/2 - 1)/(pi/2)^3) K^2
    # applied to (1, 0, 0) gives (2/pi, 2/pi, 0).
    pose = se3_exp(t64([1.0, 0.0, 0.0, 0.0, 0.0, math.pi / 2]))
    expected = np.eye(4)
    expected[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    expected[:3, 3] = [2 / math.pi, 2 / math.pi, 0.0]
    assert_close(pose, expected, TIGHT)
    assert_close(se3_exp(t64([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])), _translation(1.0, 2.0, 3.0), 0.0)


def _translation(x: float, y: float, z: float) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


# --- quaternions --------------------------------------------------------------------------


def test_quaternion_to_matrix_matches_scipy_and_normalises() -> None:
    rng = np.random.default_rng(2)
    q = rng.normal(size=(500, 4)) * rng.uniform(0.1, 10.0, size=(500, 1))
    assert_close(quaternion_to_matrix(t64(q)), Rotation.from_quat(q).as_matrix(), TIGHT)


@pytest.mark.parametrize("kind", ALL_KINDS)
def test_matrix_to_quaternion_matches_scipy(kind: str) -> None:
    rotation = Rotation.from_rotvec(rotvecs(kind))
    q = matrix_to_quaternion(t64(rotation.as_matrix()))
    assert torch.all(q[:, 3] >= 0)
    assert_close(torch.linalg.vector_norm(q, dim=-1), np.ones(len(q)), TIGHT)
    assert_close_up_to_sign(q, rotation.as_quat(), TIGHT)
    # And back: R -> q -> R.
    assert_close(quaternion_to_matrix(q), rotation.as_matrix(), TIGHT)


def test_quaternion_round_trip_up_to_sign() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(500, 4))
    q[:5] = [[0, 0, 0, 1], [0, 0, 0, -1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1e-9, 1]]
    unit = q / np.linalg.norm(q, axis=1, keepdims=True)
    assert_close_up_to_sign(matrix_to_quaternion(quaternion_to_matrix(t64(q))), unit, TIGHT)


def test_quaternion_gradients() -> None:
    gen = torch.Generator().manual_seed(4)
    q = torch.randn(6, 4, dtype=torch.float64, generator=gen).requires_grad_()
    assert torch.autograd.gradcheck(quaternion_to_matrix, (q,))
    q32 = torch.randn(6, 4, generator=gen).requires_grad_()
    quaternion_to_matrix(q32).square().sum().backward()
    assert q32.grad is not None and torch.isfinite(q32.grad).all()
    # A unit-norm rescaling of q does not change R: the gradient is orthogonal to q.
    q_unit = torch.tensor([0.1, -0.3, 0.2, 0.9], dtype=torch.float64, requires_grad=True)
    (
        quaternion_to_matrix(q_unit) * torch.arange(9.0, dtype=torch.float64).view(3, 3)
    ).sum().backward()
    assert abs(torch.dot(q_unit.grad, q_unit.detach()).item()) < TIGHT


def test_pose_from_quaternion_translation_round_trip() -> None:
    rng = np.random.default_rng(5)
    q = rng.normal(size=(4, 7, 4))
    t = rng.normal(size=(4, 7, 3))
    pose = pose_from_quaternion_translation(t64(q), t64(t))
    assert pose.shape == (4, 7, 4, 4)
    assert_close(pose[..., 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (4, 7, 4)), 0.0)
    q_back, t_back = quaternion_translation_from_pose(pose)
    assert_close(t_back, t, 0.0)
    assert_close_up_to_sign(q_back, q / np.linalg.norm(q, axis=-1, keepdims=True), TIGHT)
    # Broadcasting one translation over a batch of quaternions.
    assert pose_from_quaternion_translation(t64(q), t64(t[0, 0])).shape == (4, 7, 4, 4)


# --- series coefficients -----------------------------------------------------------------


@pytest.mark.parametrize(
    "angle", [0.0, 1e-6, 1e-3, 1e-2, 0.05, 0.0999, 0.1, 0.1001, 0.3, 1.0, 3.0, math.pi]
)
def test_series_coefficients_match_high_precision(angle: float) -> None:
    mpmath = pytest.importorskip("mpmath")
    mpmath.mp.dps = 40
    t = mpmath.mpf(angle)
    if angle == 0.0:
        exact = [1, mpmath.mpf(1) / 2, mpmath.mpf(1) / 6, mpmath.mpf(1) / 12]
    else:
        exact = [
            mpmath.sin(t) / t,
            (1 - mpmath.cos(t)) / t**2,
            (t - mpmath.sin(t)) / t**3,
            1 / t**2 - mpmath.cot(t / 2) / (2 * t),
        ]
    theta_sq = t64(angle * angle)
    values = [*rotation_module._rotation_coefficients(theta_sq)]
    values.append(pose_module._inverse_jacobian_coefficient(theta_sq))
    for value, reference in zip(values, exact, strict=True):
        # Series: float64 rounding. Closed forms (angle >= 0.1) lose ~1e-15 / angle^2 to
        # cancellation, which is why the series take over below 0.1.
        rel = 4e-16 if angle < 0.1 else 2e-15 / angle**2
        assert value.item() == pytest.approx(float(reference), rel=rel)


# --- SO(3) --------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ALL_KINDS)
def test_so3_exp_matches_scipy(kind: str) -> None:
    omega = rotvecs(kind)
    assert_close(so3_exp(t64(omega)), Rotation.from_rotvec(omega).as_matrix(), TIGHT)


@pytest.mark.parametrize("kind", ["random", "tiny", "zero", "series_edge", "below_pi"])
def test_so3_log_matches_scipy(kind: str) -> None:
    omega = rotvecs(kind)
    matrices = t64(Rotation.from_rotvec(omega).as_matrix())
    tol = NEAR_PI if kind == "below_pi" else TOL
    assert_close(so3_log(matrices), Rotation.from_matrix(matrices.numpy()).as_rotvec(), tol)
    assert_close(so3_log(matrices), omega, tol)


@pytest.mark.parametrize("kind", ["tiny", "series_edge"])
def test_so3_log_small_angles_keep_relative_precision(kind: str) -> None:
    # Matrix entries carry ~1e-16 absolute error, so the relative error of the
    # logarithm can be at best ~1e-16 / angle.
    omega = t64(rotvecs(kind))
    log = so3_log(so3_exp(omega))
    angle = omega.norm(dim=-1)
    relative = (log - omega).norm(dim=-1) / angle
    assert torch.all(relative < 1e-15 / angle + 1e-15)


def test_so3_log_at_pi_up_to_sign() -> None:
    omega = rotvecs("pi")
    matrices = t64(Rotation.from_rotvec(omega).as_matrix())
    log = so3_log(matrices)
    assert_close(log.norm(dim=-1), np.full(len(omega), math.pi), TIGHT)
    assert_close_up_to_sign(log, omega, NEAR_PI)
    assert_close(so3_exp(log), matrices.numpy(), TOL)


@pytest.mark.parametrize("kind", ALL_KINDS)
def test_so3_exp_log_exp_is_identity_on_matrices(kind: str) -> None:
    matrices = t64(Rotation.from_rotvec(rotvecs(kind)).as_matrix())
    assert_close(so3_exp(so3_log(matrices)), matrices.numpy(), TOL)


def test_so3_exp_matches_matrix_exponential() -> None:
    omega = t64(rotvecs("random"))
    xi = torch.cat((torch.zeros_like(omega), omega), dim=-1)
    assert_close(so3_exp(omega), torch.linalg.matrix_exp(hat4(xi))[:, :3, :3], TIGHT)


def test_so3_gradients_finite_at_zero_and_pi() -> None:
    for omega in ([0.0, 0.0, 0.0], [1e-7, -2e-7, 0.0], [0.3, -0.2, 0.5], [0.0, 0.0, 3.0]):
        w = t64(omega).requires_grad_()
        assert torch.autograd.gradcheck(so3_exp, (w,))
        rot = so3_exp(w.detach()).requires_grad_()
        assert torch.autograd.gradcheck(so3_log, (rot,))


# --- SE(3) --------------------------------------------------------------------------------


def _twists(kind: str, seed: int = 6) -> torch.Tensor:
    omega = rotvecs(kind, seed)
    v = np.random.default_rng(seed + 100).normal(size=omega.shape) * 2.0
    return t64(np.concatenate((v, omega), axis=-1))


@pytest.mark.parametrize("kind", ALL_KINDS)
def test_se3_exp_matches_matrix_exponential(kind: str) -> None:
    xi = _twists(kind)
    assert_close(se3_exp(xi), torch.linalg.matrix_exp(hat4(xi)), TOL)


@pytest.mark.parametrize("kind", ["random", "tiny", "zero", "series_edge", "below_pi"])
def test_se3_log_inverts_exp(kind: str) -> None:
    xi = _twists(kind)
    tol = NEAR_PI if kind == "below_pi" else TOL
    assert_close(se3_log(se3_exp(xi)), xi.numpy(), tol)


@pytest.mark.parametrize("kind", ALL_KINDS)
def test_se3_exp_of_log_is_identity_on_poses(kind: str) -> None:
    xi = _twists(kind)
    poses = torch.linalg.matrix_exp(hat4(xi))
    assert_close(se3_exp(se3_log(poses)), poses.numpy(), TOL)


def test_se3_log_of_random_poses_and_rotation_part() -> None:
    poses = random_poses(300)
    xi = se3_log(poses)
    assert_close(se3_exp(xi), poses.numpy(), TOL)
    assert_close(xi[:, 3:], Rotation.from_matrix(poses[:, :3, :3].numpy()).as_rotvec(), TOL)


def test_se3_gradients() -> None:
    for omega in ([0.0, 0.0, 0.0], [1e-7, 0.0, 2e-7], [0.3, -0.2, 0.5], [0.0, 2.9, 0.0]):
        xi = torch.cat((t64([0.1, 0.2, -0.3]), t64(omega))).requires_grad_()
        assert torch.autograd.gradcheck(se3_exp, (xi,))
        pose = se3_exp(xi.detach()).requires_grad_()
        assert torch.autograd.gradcheck(se3_log, (pose,))


def test_compose_and_invert() -> None:
    a, b = random_poses(50, seed=7), random_poses(50, seed=8)
    assert_close(compose(a, b), (a @ b).numpy(), 0.0)
    inv = invert(a)
    assert_close(inv, torch.linalg.inv(a).numpy(), TOL)
    assert_close(inv @ a, np.broadcast_to(np.eye(4), (50, 4, 4)), TOL)
    assert_close(inv[:, 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (50, 4)), 0.0)
    assert_close(invert(inv), a.numpy(), TOL)
    assert_close(compose(a[0], b), (a[0] @ b).numpy(), 0.0)  # broadcasting


# --- interpolation / extrapolation -----------------------------------------------------------


def test_interpolation_endpoints_and_extrapolation() -> None:
    t0, t1 = random_poses(20, seed=9), random_poses(20, seed=10)
    assert_close(interpolate_pose(t0, t1, 0.0), t0.numpy(), TOL)
    assert_close(interpolate_pose(t0, t1, 1.0), t1.numpy(), 1e-8)  # random angles up to pi
    relative = invert(t0) @ t1
    assert_close(interpolate_pose(t0, t1, 2.0), (t1 @ relative).numpy(), 1e-8)
    s = t64(np.linspace(0.0, 1.0, 20))
    per_pose = interpolate_pose(t0, t1, s)
    assert_close(per_pose[0], t0[0].numpy(), TOL)
    assert_close(per_pose[-1], t1[-1].numpy(), 1e-8)


def test_interpolation_midpoint_of_pure_translation() -> None:
    rot = Rotation.from_rotvec([0.2, -0.4, 0.1]).as_matrix()
    t0, t1 = _translation(1.0, 2.0, 3.0), _translation(3.0, -2.0, 4.0)
    t0[:3, :3] = t1[:3, :3] = rot
    mid = interpolate_pose(t64(t0), t64(t1), 0.5)
    expected = t0.copy()
    expected[:3, 3] = [2.0, 0.0, 3.5]
    assert_close(mid, expected, TIGHT)


def _rotation_about_axis_through(centre: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the z-parallel axis through ``centre``."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
    out[:3, 3] = centre - out[:3, :3] @ centre
    return out


def test_interpolation_midpoint_of_pure_rotation() -> None:
    t0 = np.eye(4)
    t0[:3, :3] = Rotation.from_rotvec([0.0, 0.0, 0.2]).as_matrix()
    t1 = np.eye(4)
    t1[:3, :3] = Rotation.from_rotvec([0.0, 0.0, 1.4]).as_matrix()
    expected = np.eye(4)
    expected[:3, :3] = Rotation.from_rotvec([0.0, 0.0, 0.8]).as_matrix()
    assert_close(interpolate_pose(t64(t0), t64(t1), 0.5), expected, TIGHT)
    # About an axis that does not pass through the origin: the axis stays fixed.
    centre = np.array([1.0, -2.0, 0.5])
    a = _rotation_about_axis_through(centre, -0.3)
    b = _rotation_about_axis_through(centre, 2.5)
    mid = _rotation_about_axis_through(centre, 1.1)
    assert_close(interpolate_pose(t64(a), t64(b), 0.5), mid, TOL)


def test_constant_velocity_extrapolation_reproduces_constant_twist() -> None:
    start = random_poses(8, seed=11)
    xi = _twists("random")[:8] * 0.3
    step = se3_exp(xi)
    sequence = [start]
    for _ in range(3):
        sequence.append(sequence[-1] @ step)
    predicted = extrapolate_constant_velocity(sequence[1], sequence[2])
    assert_close(predicted, sequence[3].numpy(), TOL)
    distance, angle = pose_distance(predicted, sequence[3])
    assert distance.max().item() < TOL and angle.max().item() < TOL
    # Standing still predicts standing still.
    assert_close(extrapolate_constant_velocity(start, start), start.numpy(), TOL)


def test_constant_velocity_prediction_of_predictions_stays_rigid() -> None:
    """Predictions from poses that were predictions (corrected by exp(xi) T, as the
    SDF tracker does): R_k R_(k-1)^T R_k multiplied float32's orthonormality error by
    ~2.4 a frame, so without pulling the rotation back onto SO(3) it passed 1 after ~20
    frames and overflowed after ~25; each prediction must stay a rotation and keep its
    speed."""
    step = se3_exp(torch.tensor([0.007, 0.001, 0.002, 0.003, 0.005, 0.001]))
    poses = [torch.eye(4), step]
    for _ in range(60):
        poses.append(extrapolate_constant_velocity(poses[-2], poses[-1]))
    rotation = poses[-1][:3, :3]
    assert torch.isfinite(poses[-1]).all()
    assert (rotation @ rotation.T - torch.eye(3)).abs().max().item() < 1e-5
    exact = torch.linalg.matrix_power(step.double(), len(poses) - 1)
    distance, angle = pose_distance(poses[-1].double(), exact)
    assert distance.item() < 1e-4 and angle.item() < 1e-4


def test_renormalise_rotation_matches_the_polar_factor() -> None:
    rotation = random_poses(16, seed=5)[:, :3, :3]
    noisy = (
        rotation + 1e-3 * torch.randn(16, 3, 3, generator=torch.Generator().manual_seed(2)).double()
    )
    fixed = renormalise_rotation(noisy)
    assert_close(fixed, orthonormalize_rotation(noisy).numpy(), 1e-10)
    assert_close(renormalise_rotation(rotation), rotation.numpy(), TIGHT)
    assert renormalise_rotation(noisy.float()).dtype == torch.float32


# --- orthonormalisation and distances -------------------------------------------------------


def test_orthonormalize_rotation_matches_polar_decomposition() -> None:
    rng = np.random.default_rng(12)
    rot = Rotation.random(30, random_state=rng).as_matrix()
    noisy = rot + rng.normal(scale=4e-4, size=rot.shape)
    fixed = orthonormalize_rotation(t64(noisy))
    eye = np.broadcast_to(np.eye(3), (30, 3, 3))
    assert_close(fixed.transpose(-1, -2) @ fixed, eye, TIGHT)
    assert_close(torch.linalg.det(fixed), np.ones(30), TIGHT)
    polar = np.stack([scipy.linalg.polar(m)[0] for m in noisy])
    assert_close(fixed, polar, TIGHT)
    assert_close(orthonormalize_rotation(t64(rot)), rot, TIGHT)
    # A reflection is mapped to a proper rotation, never to det -1.
    reflection = t64(np.diag([1.0, 1.0, -1.0]) @ rot[0])
    assert torch.linalg.det(orthonormalize_rotation(reflection)).item() == pytest.approx(1.0)


def test_rotation_angle_and_pose_distance() -> None:

    rotvec = rotvecs("random")
    matrices = t64(Rotation.from_rotvec(rotvec).as_matrix())
    assert_close(rotation_angle(matrices), np.linalg.norm(rotvec, axis=-1), TOL)
    assert_close(
        rotation_angle(t64(Rotation.from_rotvec(rotvecs("tiny")).as_matrix())),
        np.linalg.norm(rotvecs("tiny"), axis=-1),
        1e-15,
    )
    a = random_poses(40, seed=14)
    b = random_poses(40, seed=15)
    distance, angle = pose_distance(a, b)
    assert_close(distance, np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=-1), TIGHT)
    relative = Rotation.from_matrix(a[:, :3, :3].numpy()).inv() * Rotation.from_matrix(
        b[:, :3, :3].numpy()
    )
    assert_close(angle, relative.magnitude(), TOL)
    same_distance, same_angle = pose_distance(a, a)
    assert same_distance.abs().max().item() == 0.0 and same_angle.max().item() < 1e-15


# --- dtypes and shapes ----------------------------------------------------------------------


def test_float32() -> None:
    xi = _twists("random")[:50].float()
    pose = se3_exp(xi)
    assert pose.dtype == torch.float32
    assert_close(se3_log(pose), xi.numpy(), 1e-4)
    assert_close(pose, se3_exp(xi.double()).numpy(), 1e-5)
    q = matrix_to_quaternion(pose[:, :3, :3])
    assert q.dtype == torch.float32
    assert_close(quaternion_to_matrix(q), pose[:, :3, :3].detach().numpy(), 1e-5)
    tiny = t64(rotvecs("tiny")).float()
    assert_close(so3_log(so3_exp(tiny)), tiny.numpy(), 1e-7)
    assert_close(invert(pose) @ pose, np.broadcast_to(np.eye(4), (50, 4, 4)), 1e-5)
    assert interpolate_pose(pose, pose.flip(0), 0.5).dtype == torch.float32


def test_batched_shapes() -> None:
    gen = torch.Generator().manual_seed(16)
    q = torch.randn(5, 7, 4, dtype=torch.float64, generator=gen)
    rot = quaternion_to_matrix(q)
    assert rot.shape == (5, 7, 3, 3)
    assert matrix_to_quaternion(rot).shape == (5, 7, 4)
    omega = torch.randn(5, 7, 3, dtype=torch.float64, generator=gen)
    assert so3_exp(omega).shape == (5, 7, 3, 3)
    assert so3_log(so3_exp(omega)).shape == (5, 7, 3)
    xi = torch.randn(5, 7, 6, dtype=torch.float64, generator=gen)
    pose = se3_exp(xi)
    assert pose.shape == (5, 7, 4, 4)
    assert se3_log(pose).shape == (5, 7, 6)
    assert invert(pose).shape == (5, 7, 4, 4)
    assert rotation_angle(rot).shape == (5, 7)
    assert all(d.shape == (5, 7) for d in pose_distance(pose, pose[0]))
    assert orthonormalize_rotation(rot).shape == (5, 7, 3, 3)
    assert interpolate_pose(pose, pose, torch.rand(5, 7, generator=gen)).shape == (5, 7, 4, 4)
    assert extrapolate_constant_velocity(pose, pose).shape == (5, 7, 4, 4)
    # Batched results equal the per-element results.
    flat = se3_exp(xi.reshape(-1, 6)).reshape(5, 7, 4, 4)
    assert_close(pose, flat.numpy(), 0.0)


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_device() -> None:
    xi = _twists("random")[:20].cuda()
    pose = se3_exp(xi)
    assert pose.device.type == "cuda"
    assert_close(se3_log(pose).cpu(), xi.cpu().numpy(), TOL)
    assert matrix_to_quaternion(pose[:, :3, :3]).device.type == "cuda"
    assert orthonormalize_rotation(pose[:, :3, :3]).device.type == "cuda"
