"""The tracker seam: the protocol every tracker implements, the registry behind
``tracking.method``, and the motion model that gives each frame its starting pose.

A new tracker is a class with ``track(field, view, initial_pose, generator)``,
registered in :data:`TRACKERS` (a built-in one's name is also in the config's
``tracking.method``); the run loop does not change.
"""

from __future__ import annotations

import dataclasses

import torch

from eslam.config import ESLAMConfig, HybridTrackerConfig, RenderTrackerConfig, SdfTrackerConfig
from eslam.geometry.pose import extrapolate_constant_velocity
from eslam.registry import Registry
from eslam.slam.cuda_graphs import GraphedRenderTracker
from eslam.slam.tracking.base import Tracker
from eslam.slam.tracking.hybrid import HybridTracker
from eslam.slam.tracking.render import (
    RenderTracker,
    TrackingSettings,
    compiled_tracking_loss,
    tracking_loss,
)
from eslam.slam.tracking.sdf import SdfTracker


def _renderer(config: ESLAMConfig, settings: TrackingSettings) -> RenderTracker:
    """The rendering tracker with ``settings``; with ``compute.cuda_graphs`` not off, the
    one that replays CUDA graphs where it can (:mod:`eslam.slam.cuda_graphs`; the replays
    do not use the compiled loss); its loss compiled with ``compute.compile: tracking``."""
    loss = compiled_tracking_loss() if config.compute.compile == "tracking" else tracking_loss
    if config.compute.cuda_graphs == "off":
        return RenderTracker(settings, loss)
    return GraphedRenderTracker(settings, loss, mode=config.compute.cuda_graphs)


def _render_tracker(config: ESLAMConfig) -> RenderTracker:
    return _renderer(config, TrackingSettings(config.tracking.render, config.render, config.loss))


def _sdf_tracker(config: ESLAMConfig) -> SdfTracker:
    return SdfTracker(config.tracking.sdf)


def _hybrid_tracker(config: ESLAMConfig) -> HybridTracker:
    hybrid, render = config.tracking.hybrid, config.tracking.render
    render = dataclasses.replace(
        render,
        iterations=hybrid.render_iterations,
        lr_translation=render.lr_translation * hybrid.lr_factor,
        lr_rotation=render.lr_rotation * hybrid.lr_factor,
    )
    settings = TrackingSettings(render, config.render, config.loss)
    return HybridTracker(_sdf_tracker(config), _renderer(config, settings))


TRACKERS: Registry[Tracker] = Registry("tracker", "tracking.method")
"""Trackers by ``tracking.method``; a factory takes the run's config."""
TRACKERS.register("render", _render_tracker, config=RenderTrackerConfig)
TRACKERS.register("sdf", _sdf_tracker, config=SdfTrackerConfig)
TRACKERS.register("hybrid", _hybrid_tracker, config=HybridTrackerConfig)


def make_tracker(config: ESLAMConfig) -> Tracker:
    """The tracker ``config.tracking.method`` names, built from its config section.

    Raises:
        ConfigError: no tracker has that name.
    """
    return TRACKERS.make(config.tracking.method, config)


def predict_pose(poses: torch.Tensor, constant_velocity: bool) -> torch.Tensor:
    """The motion model: the starting pose of the next frame from the (K, 4, 4) poses so far.

    Constant velocity on SE(3) (:func:`~eslam.geometry.pose.extrapolate_constant_velocity`)
    from the last two poses when ``constant_velocity`` and K >= 2, else the last pose.
    """
    if len(poses) == 0:
        raise ValueError("the motion model needs at least one earlier pose")
    if constant_velocity and len(poses) >= 2:
        return extrapolate_constant_velocity(poses[-2], poses[-1])
    return poses[-1]


def motion_guess(poses: torch.Tensor, constant_velocity: bool, after_failure: bool) -> torch.Tensor:
    """The next frame's starting pose as the run takes it: :func:`predict_pose`, holding
    still (no velocity) right after a failed frame, whose pose is a guess and not
    evidence of motion."""
    return predict_pose(poses, constant_velocity and not after_failure)
