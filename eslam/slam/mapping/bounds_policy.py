"""The scene bound during a run: estimated at start when not given, grown as keyframes see more.

Start: without ``scene.bound`` the bound is frame 0's depth points (seen from frame 0's
pose: ground truth when the sequence has it, else the identity) and camera centre,
0.5-99.5 percentiles per axis, plus ``scene.auto_bound_margin`` metres. No ground truth
beyond frame 0 is used, so it works for any sensor.

During the run: every new keyframe's depth (subsampled) is back-projected with its
estimated pose. When more than ``scene.grow_threshold`` of its points lie outside the
bound, the bound and the feature planes grow (learnt features kept) to hold the
points plus ``scene.grow_margin``; with ``scene.grow`` off, or when growth would pass
``scene.max_extent``, a warning gives the share of points outside, once per run.
Points outside the bound are never dropped silently: they read the planes' border.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch

from eslam.config import SceneConfig
from eslam.errors import ConfigError, InputError
from eslam.field.scene_field import SceneField
from eslam.geometry.bounds import bound_coverage, depth_points, estimate_bound
from eslam.types import Frame, Intrinsics

log = logging.getLogger("eslam")


AUTO_BOUND_SEARCH = 30
"""Frames searched, from frame 0, for the first with valid depth to estimate the bound."""


def first_pose(frame: Frame, logger: logging.Logger = log) -> torch.Tensor:
    """(4, 4) float32 pose of frame 0: its ground truth (it fixes the world frame), else identity.

    Frame 0 without usable ground truth (none, or a NaN matrix, e.g. ScanNet's lost
    tracking) starts at the identity; with a NaN matrix a warning says so: the world
    frame then differs from the ground truth's, which a configured scene.bound may not
    fit (the ATE aligns the two).
    """
    if frame.pose_gt is None:
        return torch.eye(4)
    if not np.all(np.isfinite(frame.pose_gt)):
        logger.warning(
            "frame 0 has no usable ground-truth pose: the run starts at the identity, so "
            "its world frame differs from the ground truth's (a configured scene.bound "
            "may not fit; the ATE aligns the two)"
        )
        return torch.eye(4)
    return torch.from_numpy(frame.pose_gt).float()


def _format(bound: torch.Tensor) -> str:
    return str([[round(float(v), 3) for v in row] for row in bound.tolist()])


def check_depth_found(frames_without_depth: int, source: str) -> None:
    """Refuse a source whose first AUTO_BOUND_SEARCH frames have no depth (no bound set).

    Raises:
        InputError: ``frames_without_depth`` reached :data:`AUTO_BOUND_SEARCH`.
    """
    if frames_without_depth >= AUTO_BOUND_SEARCH:
        raise InputError(
            Path(source),
            f"none of the first {AUTO_BOUND_SEARCH} frames has valid depth, so no scene "
            "bound can be estimated",
            "check the depth images, or set scene.bound=[[xmin,xmax],[ymin,ymax],[zmin,zmax]]",
        )


def check_some_depth(index: int, total: int | None, keyframes: int, source: str) -> None:
    """Refuse a run whose every frame lacks valid depth, at its last frame ``index``.

    Such a run (a bound given, or fewer frames than :data:`AUTO_BOUND_SEARCH`) would
    otherwise finish with exit 0, an empty map and poses that are only predictions: the
    user must hear that the depth is missing (all zero, or unreadable as depth).

    Raises:
        InputError: ``index`` is the last of ``total`` frames and no frame was mapped
            (``keyframes`` is 0: the first frame with depth is always a keyframe).
    """
    if keyframes == 0 and total is not None and index + 1 >= total:
        raise InputError(
            Path(source),
            f"none of its {total} frames has valid depth (every depth pixel is 0), so "
            "there is nothing to map",
            "check the depth images and data.depth_scale (`eslam inspect PATH` shows their range)",
        )


def bound_from_frame(
    scene: SceneConfig, frame: Frame, pose: torch.Tensor, logger: logging.Logger = log
) -> torch.Tensor:
    """(3, 2) float32 scene bound from the first frame with depth, seen from ``pose``
    (frame 0's: the camera has barely moved yet; growth covers what this misses).

    Raises:
        ValueError: the frame has no valid depth.
        ConfigError: the estimated bound is wider than ``scene.max_extent``.
    """
    pose = pose.detach().cpu().double()
    depth = torch.tensor(frame.depth, dtype=torch.float64)  # a copy: frames may be read-only
    points = depth_points(depth, frame.intrinsics, pose)
    if len(points) == 0:
        raise ValueError("the frame has no valid depth")
    bound = estimate_bound(points, scene.auto_bound_margin, centres=pose[:3, 3]).float()
    widest = float((bound[:, 1] - bound[:, 0]).max())
    if widest > scene.max_extent:
        raise ConfigError(
            f"the scene bound estimated from frame 0's depth is {widest:.1f} m wide, more "
            f"than scene.max_extent={scene.max_extent} m: set scene.bound or raise max_extent"
        )
    logger.info(
        "scene bound estimated from the first frame with depth (%d points, margin %.2f m): %s",
        len(points),
        scene.auto_bound_margin,
        _format(bound),
    )
    return bound


def cover_keyframe(
    field: SceneField,
    depth: torch.Tensor,
    intrinsics: Intrinsics,
    pose: torch.Tensor,
    scene: SceneConfig,
    generator: torch.Generator,
    warned: bool,
    logger: logging.Logger = log,
) -> bool:
    """Grow ``field`` so it holds a keyframe's depth points, or warn (module doc).

    Args:
        field: the scene field (grown in place; build optimisers after this).
        depth: (H, W) the keyframe's depth, metres, 0 = invalid.
        intrinsics: its camera.
        pose: (4, 4) its estimated camera-to-world pose.
        scene: the bound settings.
        generator: random source on the field's device (new plane features).
        warned: whether this run has already warned about points outside the bound.
        logger: where to report growth and the warning (the run's log).

    Returns:
        The new ``warned`` flag (True once a warning was logged).
    """
    points = depth_points(depth, intrinsics, pose.to(depth))
    coverage = bound_coverage(points, field.bound, scene.grow_margin)
    if coverage.fraction_outside <= scene.grow_threshold or not coverage.grows:
        return warned
    old = field.bound.detach().clone()
    widest = float((coverage.required[:, 1] - coverage.required[:, 0]).max())
    if scene.grow and widest <= scene.max_extent:
        field.grow(coverage.required, generator)
        logger.info(
            "scene bound grown (%.1f%% of a keyframe's depth points were outside): %s -> %s",
            100.0 * coverage.fraction_outside,
            _format(old),
            _format(field.bound),
        )
        return warned
    if not warned:
        reason = (
            "scene.grow is off"
            if not scene.grow
            else f"growing would pass scene.max_extent={scene.max_extent} m ({widest:.1f} m)"
        )
        logger.warning(
            "%.1f%% of a keyframe's depth points lie outside the scene bound %s and read "
            "its border features (%s; warned once): widen scene.bound or set scene.grow=true",
            100.0 * coverage.fraction_outside,
            _format(old),
            reason,
        )
    return True
