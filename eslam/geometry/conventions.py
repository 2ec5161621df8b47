"""Camera axis conventions: the only place in eslam where camera axes are flipped.

Two conventions for the camera frame of a camera-to-world pose are in use:

- OpenCV (used everywhere inside eslam, and by TUM/ScanNet/7-Scenes style data):
  x right, y down, z forward; the camera looks down +z.
- OpenGL (NeRF, Blender, and ESLAM's public release): x right, y up, z backward;
  the camera looks down -z.

The two camera frames differ by a rotation of pi about the x axis, F = diag(1, -1, -1, 1):
a point's coordinates convert as p_opencv = F p_opengl and p_opengl = F p_opencv, and a
camera-to-world pose converts by right-multiplication, c2w_other = c2w @ F. F is its own
inverse, so the same matrix and the same operation convert in either direction. Readers
call these functions once at the boundary; nothing else in eslam flips axes.

The functions accept torch tensors and numpy arrays and return the type they are given.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import torch

ArrayT = TypeVar("ArrayT", torch.Tensor, np.ndarray)

OPENGL_FROM_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
"""(4, 4) float64 F = diag(1, -1, -1, 1), read-only; F = F^-1, so it is also OpenCV-from-OpenGL."""
OPENGL_FROM_OPENCV.setflags(write=False)

_FLIP = (1.0, -1.0, -1.0, 1.0)


def _flip_camera_axes(c2w: ArrayT) -> ArrayT:
    """c2w @ diag(1, -1, -1, 1), computed exactly by negating columns 1 and 2."""
    if isinstance(c2w, torch.Tensor):
        if c2w.shape[-2:] != (4, 4):
            raise ValueError(f"expected (..., 4, 4) poses, got shape {tuple(c2w.shape)}")
        flip = torch.tensor(_FLIP, dtype=c2w.dtype, device=c2w.device)
        return c2w * flip
    array = np.asarray(c2w)
    if array.shape[-2:] != (4, 4):
        raise ValueError(f"expected (..., 4, 4) poses, got shape {array.shape}")
    return array * np.asarray(_FLIP, dtype=np.result_type(array.dtype, np.float32))


def opengl_to_opencv_pose(c2w: ArrayT) -> ArrayT:
    """Camera-to-world pose with OpenGL camera axes -> the same camera with OpenCV axes.

    c2w_opencv = c2w_opengl @ diag(1, -1, -1, 1): the y and z columns (camera up and
    backward directions in the world) are negated, the camera centre is unchanged.
    The operation is its own inverse (identical to ``opencv_to_opengl_pose``).

    Args:
        c2w: (..., 4, 4) torch tensor or numpy array.

    Returns:
        (..., 4, 4) pose of the same type, dtype and device as the input (integer
        numpy arrays come back as float64).
    """
    return _flip_camera_axes(c2w)


def opencv_to_opengl_pose(c2w: ArrayT) -> ArrayT:
    """Camera-to-world pose with OpenCV camera axes -> the same camera with OpenGL axes.

    c2w_opengl = c2w_opencv @ diag(1, -1, -1, 1); its own inverse (identical to
    ``opengl_to_opencv_pose``).

    Args:
        c2w: (..., 4, 4) torch tensor or numpy array.

    Returns:
        (..., 4, 4) pose of the same type, dtype and device as the input (integer
        numpy arrays come back as float64).
    """
    return _flip_camera_axes(c2w)
