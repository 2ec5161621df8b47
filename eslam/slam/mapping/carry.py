"""Frames between keyframes follow their keyframes' refined poses (``mapping.carry_frames``).

Mapping refines the window's keyframe poses with the map (the paper's joint
optimisation); the frames tracked between keyframes keep the pose tracking gave them.
Their neighbours move and they do not, so every keyframe becomes a step in the
trajectory (on TUM fr1/xyz the frame-to-frame error of pairs with a keyframe is over
twice that of the others: docs/results.md). ORB-SLAM keeps each frame's pose relative
to a reference keyframe and reads the final trajectory through the optimised keyframes
(Mur-Artal et al. 2015, section VIII); here a frame is carried by both keyframes around
it, weighed by where it lies between them.

For a keyframe k moved from T_k to T'_k, its correction is C_k = T'_k T_k^-1 (the
identity for a keyframe that did not move). A frame f between keyframes a < f < b is
carried by each and the two results are blended along the SE(3) geodesic
(:func:`eslam.geometry.pose.interpolate_pose`):

    T'_f = interp(C_a T_f, C_b T_f, s),    s = (f - a) / (b - a)

so a frame next to a keyframe moves as that keyframe does, and equal corrections move
the whole stretch rigidly. A frame after the last keyframe (tracked while a mapping call
ran beside the tracker) moves with it: T'_f = C_a T_f. Keyframes' own poses are not
touched.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence

import torch

from eslam.geometry.pose import interpolate_pose, invert


def corrections(before: torch.Tensor, after: torch.Tensor) -> torch.Tensor:
    """C = T' T^-1 per pose: (K, 4, 4) from (K, 4, 4) poses before and after."""
    return after @ invert(before)


def carried_poses(
    poses: torch.Tensor, keyframe_frames: Sequence[int], moved: Mapping[int, torch.Tensor]
) -> tuple[list[int], torch.Tensor]:
    """The frames that move because keyframes moved, and their new poses (module doc).

    Args:
        poses: (N, 4, 4) every frame's camera-to-world pose so far (the trajectory).
        keyframe_frames: the keyframes' frame indices, increasing.
        moved: frame index of a moved keyframe -> its correction C_k (4, 4).

    Returns:
        The indices of the frames carried (keyframes excluded, increasing) and their
        (M, 4, 4) poses; empty when nothing moved.
    """
    keyframes = list(keyframe_frames)
    if any(b <= a for a, b in itertools.pairwise(keyframes)):
        raise ValueError(f"keyframe frames must increase, got {keyframes}")
    count = poses.shape[0]
    frames: list[int] = []
    first: list[torch.Tensor] = []
    second: list[torch.Tensor] = []
    shares: list[float] = []
    eye = torch.eye(4, dtype=poses.dtype, device=poses.device)
    bounds = [*keyframes, count]
    for j, (a, b) in enumerate(itertools.pairwise(bounds)):
        last = j == len(keyframes) - 1
        move_a, move_b = moved.get(a), None if last else moved.get(b)
        if move_a is None and move_b is None:
            continue
        for f in range(a + 1, min(b, count)):
            frames.append(f)
            first.append(eye if move_a is None else move_a)
            second.append(first[-1] if last else (eye if move_b is None else move_b))
            shares.append(0.0 if last else (f - a) / (b - a))
    if not frames:
        return [], poses.new_zeros((0, 4, 4))
    originals = poses[frames]
    from_a = torch.stack(first).to(poses.dtype) @ originals
    from_b = torch.stack(second).to(poses.dtype) @ originals
    share = torch.tensor(shares, dtype=poses.dtype, device=poses.device)
    return frames, interpolate_pose(from_a, from_b, share)
