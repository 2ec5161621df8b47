"""OpenCV <-> OpenGL camera axis flips on torch tensors and numpy arrays."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from eslam.geometry import OPENGL_FROM_OPENCV, opencv_to_opengl_pose, opengl_to_opencv_pose


def random_poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.random(n, random_state=rng).as_matrix()
    poses[:, :3, 3] = rng.normal(size=(n, 3))
    return poses


def test_constant() -> None:
    np.testing.assert_array_equal(OPENGL_FROM_OPENCV, np.diag([1.0, -1.0, -1.0, 1.0]))
    assert OPENGL_FROM_OPENCV.dtype == np.float64
    np.testing.assert_array_equal(OPENGL_FROM_OPENCV @ OPENGL_FROM_OPENCV, np.eye(4))
    with pytest.raises(ValueError):
        OPENGL_FROM_OPENCV[0, 0] = 2.0


def test_equals_right_multiplication_by_the_constant() -> None:
    poses = random_poses(10)
    np.testing.assert_allclose(opencv_to_opengl_pose(poses), poses @ OPENGL_FROM_OPENCV, atol=0)
    np.testing.assert_allclose(opengl_to_opencv_pose(poses), poses @ OPENGL_FROM_OPENCV, atol=0)


@pytest.mark.parametrize("to_torch", [False, True])
def test_flipping_twice_is_identity(to_torch: bool) -> None:
    poses = random_poses(10, seed=1)
    x = torch.as_tensor(poses) if to_torch else poses
    for once in (opencv_to_opengl_pose, opengl_to_opencv_pose):
        back = opengl_to_opencv_pose(once(x))
        assert type(back) is type(x)
        np.testing.assert_array_equal(np.asarray(back), poses)  # exact: only sign flips
        np.testing.assert_array_equal(np.asarray(once(once(x))), poses)


def test_viewing_direction_and_up() -> None:
    # OpenCV identity camera: looks down world +z, image "up" is world -y.
    gl = opencv_to_opengl_pose(np.eye(4))
    forward_gl_world = gl[:3, :3] @ np.array([0.0, 0.0, -1.0])  # OpenGL looks down -z
    np.testing.assert_array_equal(forward_gl_world, [0.0, 0.0, 1.0])
    up_gl_world = gl[:3, :3] @ np.array([0.0, 1.0, 0.0])  # OpenGL y is up
    np.testing.assert_array_equal(up_gl_world, [0.0, -1.0, 0.0])
    # Same for a random camera: same centre, same viewing ray, opposite local axes.
    cv = random_poses(1, seed=2)[0]
    gl = opencv_to_opengl_pose(cv)
    np.testing.assert_array_equal(gl[:3, 3], cv[:3, 3])
    np.testing.assert_array_equal(gl[:3, 2], -cv[:3, 2])
    np.testing.assert_array_equal(gl[:3, 1], -cv[:3, 1])
    np.testing.assert_array_equal(gl[:3, 0], cv[:3, 0])


def test_point_in_front_has_positive_z_in_opencv_and_negative_in_opengl() -> None:
    cv = random_poses(1, seed=3)[0]
    point = cv[:3, 3] + 2.5 * cv[:3, 2] + 0.3 * cv[:3, 0]  # in front, a bit to the right
    gl = opencv_to_opengl_pose(cv)
    in_cv = np.linalg.inv(cv) @ np.append(point, 1.0)
    in_gl = np.linalg.inv(gl) @ np.append(point, 1.0)
    np.testing.assert_allclose(in_cv[:3], [0.3, 0.0, 2.5], atol=1e-12)
    np.testing.assert_allclose(in_gl[:3], [0.3, 0.0, -2.5], atol=1e-12)
    np.testing.assert_allclose(in_gl, OPENGL_FROM_OPENCV @ in_cv, atol=1e-12)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_torch_keeps_dtype_device_batch_and_gradients(dtype: torch.dtype) -> None:
    poses = torch.as_tensor(random_poses(6, seed=4), dtype=dtype).reshape(2, 3, 4, 4)
    poses.requires_grad_()
    out = opencv_to_opengl_pose(poses)
    assert isinstance(out, torch.Tensor)
    assert out.dtype == dtype and out.device == poses.device and out.shape == (2, 3, 4, 4)
    out.sum().backward()
    expected_grad = torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=dtype).expand(2, 3, 4, 4)
    torch.testing.assert_close(poses.grad, expected_grad)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_numpy_keeps_dtype_and_does_not_modify_input(dtype: type) -> None:
    poses = random_poses(3, seed=5).astype(dtype)
    original = poses.copy()
    out = opengl_to_opencv_pose(poses)
    assert isinstance(out, np.ndarray) and out.dtype == dtype and out.shape == (3, 4, 4)
    np.testing.assert_array_equal(poses, original)
    assert opengl_to_opencv_pose(np.eye(4, dtype=np.int64)).dtype == np.float64


def test_rejects_non_pose_shapes() -> None:
    with pytest.raises(ValueError, match="4, 4"):
        opencv_to_opengl_pose(np.eye(3))
    with pytest.raises(ValueError, match="4, 4"):
        opengl_to_opencv_pose(torch.zeros(4, 3))
