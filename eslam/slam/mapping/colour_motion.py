"""A keyframe's colour moved to its depth image's time (``mapping.colour_motion``).

A sensor whose colour and depth streams are not synchronised (the Kinect of TUM RGB-D)
takes a frame's colour image ``delay`` seconds after its depth image (before, for a
negative delay; :attr:`eslam.types.Frame.colour_delay`). The camera moves in between,
so the colour lies beside the geometry by that motion, and mapping, which fits colour
and depth at one pose, pulls the keyframe's pose between the two. Here each depth
pixel takes the colour of where its 3-D point was seen by the colour camera.

The camera's motion over the delay is the constant velocity of the last step (the
motion model's, Kerl et al. 2013 DVO; ORB-SLAM's), as a twist in the camera's frame.
With the poses T_prev and T (camera-to-world) of the previous frame and this one,
``dt`` seconds apart:

    M = T_prev^-1 T,    T_colour = T Exp((delay / dt) Log M)

and a point X of the depth camera is at X_c = T_colour^-1 T X = Exp(-(delay / dt) Log M) X
in the colour camera's frame, seen at pixel u = K X_c (the images share K: the depth is
registered to the colour camera). Pixels without depth keep the colour as read.

In real time the last step spans the frames dropped while the run was busy (a third of
a second on a CPU), so its velocity stands for the motion over the gap poorly; there
the colour is kept as read (:func:`moves_colour`; what that measured: docs/results.md).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from eslam.data.registration import sample_bilinear
from eslam.geometry.camera import backproject_depth, project_points
from eslam.geometry.pose import invert, se3_exp, se3_log
from eslam.slam.trajectory import Trajectory
from eslam.types import Frame, Intrinsics


def moves_colour(colour_motion: bool, real_time: bool) -> bool:
    """Whether keyframes' colour is moved (``mapping.colour_motion``): on recorded data
    only (module doc)."""
    return colour_motion and not real_time


def colour_from_depth(
    previous: torch.Tensor, current: torch.Tensor, dt: float, delay: float
) -> torch.Tensor:
    """Exp(-(delay / dt) Log(T_prev^-1 T)): depth-camera to colour-camera coordinates
    (module doc), float64 (4, 4); the identity when ``dt`` is not positive."""
    previous, current = previous.double(), current.double()
    if not dt > 0:
        return torch.eye(4, dtype=torch.float64)
    twist = se3_log(invert(previous) @ current)
    return se3_exp(-(delay / dt) * twist)


def moved_pixels(
    depth: np.ndarray, intrinsics: Intrinsics, motion: torch.Tensor
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each depth pixel's 3-D point falls after ``motion`` (4, 4: depth- to
    colour-camera coordinates): u = K (R X + t). Returns (H, W) float64 u, v and the
    point's depth z after the motion (z <= 0: behind the camera, u and v meaningless)."""
    points = backproject_depth(torch.from_numpy(depth.astype(np.float64)), intrinsics)
    uv, z = project_points(points, intrinsics, invert(motion.double()))
    return uv[..., 0].numpy(), uv[..., 1].numpy(), z.numpy()


def moved_colour(
    rgb: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics, motion: torch.Tensor
) -> np.ndarray:
    """``rgb`` (H, W, 3 uint8) resampled so that each pixel with ``depth`` (H, W metres,
    0 = none) holds the colour of its 3-D point moved by ``motion`` (4, 4: depth- to
    colour-camera coordinates, :func:`colour_from_depth`); bilinear, rounded to uint8.
    Pixels without depth, or whose point falls outside the image or behind the camera,
    keep their colour."""
    u, v, z = moved_pixels(depth, intrinsics, motion)
    inside = (u >= 0) & (u <= intrinsics.width - 1) & (v >= 0) & (v <= intrinsics.height - 1)
    moved = (depth > 0) & inside & (z > 0)
    sampled = sample_bilinear(rgb, u, v)
    out = rgb.copy()
    out[moved] = np.clip(np.rint(sampled[moved]), 0, 255).astype(np.uint8)
    return out


def colour_at_depth_time(frame: Frame, trajectory: Trajectory, index: int) -> Frame:
    """``frame`` (trajectory entry ``index`` > 0, its pose tracked) with its colour moved
    to its depth image's time by the camera's last step (module doc); ``frame`` itself
    when its colour was taken with its depth (``colour_delay`` 0)."""
    if not frame.colour_delay or index < 1:
        return frame
    times = trajectory.timestamps()
    poses = trajectory.poses[index - 1 : index + 1].cpu()
    dt = float(times[index] - times[index - 1])
    motion = colour_from_depth(poses[0], poses[1], dt, frame.colour_delay)
    return replace(frame, rgb=moved_colour(frame.rgb, frame.depth, frame.intrinsics, motion))
