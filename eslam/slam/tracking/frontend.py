"""The tracking front end: one frame in, its pose and the tracker's judgement out.

:class:`TrackingFrontEnd` prepares the frame's :class:`~eslam.slam.views.View`, takes
the motion model's guess (:func:`~eslam.slam.tracking.trackers.predict_pose`; with
``tracking.start: features`` the pose image features give,
:mod:`eslam.slam.tracking.feature_start`), applies its view
filters (:mod:`eslam.slam.tracking.view_filters`), runs the tracker (``tracking.method``, from
:data:`~eslam.slam.tracking.trackers.TRACKERS`) and judges the result: a frame whose
start of features overrules the tracker keeps that start and fails
(:meth:`~eslam.slam.tracking.feature_start.FeatureStart.overrules`; no recovery: its
pose is known); a failed frame (the
tracker said so, or its pose is not finite; after a failed or untracked frame, also one
short of the recovery's inlier share) goes to the recovery
(:mod:`eslam.slam.tracking.recovery`: other starting poses, relocalisation),
and keeps the guess when nothing passes; a failed frame whose start came from its
features keeps that pose and, in real time, skips the recovery
(``tracking.recovery.carried``). With ``tracking.keyframe_offset`` the tracker's pose
of a frame it passed is moved into the mapper's frame
(:mod:`eslam.slam.tracking.keyframe_offset`: the offset is measured by tracking the
newest mapped keyframe again after each mapping call), and the overrule rule measures
the tracker's shift from its start of features there too (the start is chained from
poses in that frame). The run loop appends the
answer, a :class:`TrackedFrame`, to the trajectory; observers report it.

The front end keeps no state of its own between frames outside the run's state:
whether the last two frames failed or the last was recovered (then the motion model
holds still) is read from the run's quality rows, and the feature start's reference
features and the keyframe offset are their entries in ``state.components``; all are
checkpointed, so a run resumed right after any frame starts its next frame exactly as
the uninterrupted run does.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Protocol

import torch

from eslam.slam.context import RunContext
from eslam.slam.mapping.bounds_policy import first_pose
from eslam.slam.places.index import Places
from eslam.slam.state import SLAMState, failed_row, recovery_of
from eslam.slam.tracking.base import Tracker, TrackingQuality, judged
from eslam.slam.tracking.feature_start import FeatureStart, OverruleRule, start_shift
from eslam.slam.tracking.keyframe_offset import KeyframeOffset
from eslam.slam.tracking.recovery import Recovery
from eslam.slam.tracking.trackers import make_tracker, motion_guess
from eslam.slam.tracking.view_filters import ViewFilter, make_filters
from eslam.slam.views import View, make_view, restrict_view, upload_frame
from eslam.types import Frame


@dataclass(frozen=True, eq=False)
class TrackedFrame:
    """What the front end made of one frame.

    Attributes:
        pose: (4, 4) its camera-to-world pose on the device (the guess when it failed).
        has_depth: whether the frame has any valid depth (none: not tracked, not mapped).
        tracked: whether the tracker ran.
        quality: the tracker's judgement (None when it has none or did not run).
        emptied_by: why a view filter left no pixel to track on, in its words
            (:attr:`~eslam.slam.tracking.view_filters.ViewFilter.emptied`; the frame
            keeps the guess), else None.
        kept: by view filter name, the share of the pixels before it that it kept
            (``observed``: the share of the frame in observed space at the guess).
    """

    pose: torch.Tensor
    has_depth: bool
    tracked: bool = False
    quality: TrackingQuality | None = None
    emptied_by: str | None = None
    kept: Mapping[str, float] = field(default_factory=dict)

    @property
    def failed(self) -> bool:
        """Whether the tracker judged the frame failed (it keeps the guess, is no keyframe)."""
        return self.quality is not None and self.quality.failed

    @property
    def recovered(self) -> bool:
        """Whether the recovery found the pose after the first try failed (the back end
        makes such a frame a keyframe)."""
        return self.quality is not None and self.quality.recovery is not None


class FrontEnd(Protocol):
    """Estimates each frame's pose against the map in ``state`` (module doc)."""

    def track(self, frame: Frame, index: int, state: SLAMState) -> TrackedFrame:
        """Frame ``index`` (the next one of ``state``) tracked; ``state`` is not
        changed, except the front end's own entries in ``state.components`` (rolled back
        with the frame when it fails half way)."""
        ...


class TrackingFrontEnd:
    """The front end of the config (module doc).

    Args:
        context: the run.
        tracker: the tracker (default: ``tracking.method``'s).
        filters: the view filters (default: those the config turns on).
        recovery: what is tried after a failed frame (default: ``tracking.recovery``'s,
            None when it is off).
    """

    def __init__(
        self,
        context: RunContext,
        tracker: Tracker | None = None,
        filters: list[ViewFilter] | None = None,
        recovery: Recovery | None = None,
    ) -> None:
        self.context = context
        self.tracker = make_tracker(context.config) if tracker is None else tracker
        self.filters = make_filters(context) if filters is None else list(filters)
        settings = context.config.tracking
        places = Places(settings.features)
        if recovery is None and settings.recovery.enabled:
            recovery = Recovery(context, self.tracker, places)
        self.recovery = recovery
        overrule = None
        if settings.start_overrule_matches > 0:
            overrule = OverruleRule(
                settings.start_overrule_matches,
                settings.start_overrule_shift,
                settings.start_overrule_frames,
            )
        self.feature_start = (
            FeatureStart(
                places,
                settings.start_min_matches,
                overrule,
                settings.start_alike,
                settings.start_coarse,
            )
            if settings.start == "features"
            else None
        )
        self.offset = (
            KeyframeOffset(context, self.tracker, self.images_view, self.restricted)
            if settings.keyframe_offset
            else None
        )

    @property
    def log(self) -> logging.Logger:
        return self.context.logger

    def track(self, frame: Frame, index: int, state: SLAMState) -> TrackedFrame:
        has_depth = bool(frame.valid_depth.any())
        device = self.context.device
        if index == 0:
            return TrackedFrame(first_pose(frame, self.log).to(device), has_depth)
        guess = self.guess(state)
        if not has_depth or state.field is None or len(state.keyframes) == 0:
            return TrackedFrame(guess, has_depth)
        query = started = None
        if self.feature_start is not None:
            query = self.feature_start.describe(frame, state)
            started = self.feature_start.start(query, state)
            if started is not None:
                guess = started.pose.to(guess)
        whole = self.view(frame)
        kept: dict[str, float] = {}
        view, emptied_by = self.filtered(whole, guess, state, kept)
        if emptied_by is not None:
            return TrackedFrame(guess, has_depth, emptied_by=emptied_by, kept=kept)
        if view.sampleable_pixels() == 0:
            return TrackedFrame(guess, has_depth)
        if self.offset is not None:
            self.offset.update(state)
        result = self.tracker.track(state.field, view, guess, state.generator)
        pose, quality = judged(result, guess)
        if self.feature_start is not None and started is not None and quality is not None:
            # the start is chained from poses in the mapper's frame: compare it there
            shift = None if quality.failed else start_shift(started, self.in_map(pose, state))
            quality = replace(quality, start_matches=started.inliers, start_shift_m=shift)
            if self.feature_start.overrules(started, quality, state):
                pose, quality = guess, replace(quality, failed=True, overruled=True)
        recovery = self.recovery
        if recovery is not None and quality is not None and not quality.overruled:
            # a start from features rests on matched points, not on the failed pose
            doubted = started is None and recovery.doubts(state)
            if not quality.failed and doubted and not recovery.passes(quality):
                pose, quality = guess, replace(quality, failed=True)
            if quality.failed and (started is None or recovery.tries_carried):
                found = recovery.recover(frame, whole, guess, state, query)
                if found is not None:
                    pose, quality = found.pose, found.quality
        if not (quality is not None and quality.failed):
            pose = self.in_map(pose, state)
        if self.feature_start is not None and query is not None:
            # a failed frame keeps its features' pose: the next frame starts from it
            # (visual odometry while the map cannot confirm), not from an older keyframe
            if quality is None or not quality.failed or started is not None:
                self.feature_start.remember(query, state)
        return TrackedFrame(pose, has_depth, True, quality, kept=kept)

    def in_map(self, pose: torch.Tensor, state: SLAMState) -> torch.Tensor:
        """The tracker's ``pose`` in the mapper's frame (the keyframe offset applied, when
        it is on; else ``pose``)."""
        return pose if self.offset is None else self.offset.apply(pose, state)

    def filtered(
        self,
        view: View,
        guess: torch.Tensor,
        state: SLAMState,
        kept: dict[str, float] | None = None,
    ) -> tuple[View, str | None]:
        """``view`` restricted by the view filters at ``guess``, and why a filter left no
        pixel (its words), else None; ``kept`` receives each filter's share of pixels."""
        for view_filter in self.filters:
            restricted = restrict_view(view, view_filter.keep(view, guess, state))
            left, before = restricted.sampleable_pixels(), view.sampleable_pixels()
            if kept is not None:
                kept[view_filter.name] = left / max(before, 1)
            if left == 0 and before > 0:
                return restricted, view_filter.emptied
            view = restricted
        return view, None

    def restricted(self, view: View, pose: torch.Tensor, state: SLAMState) -> View | None:
        """:meth:`filtered`'s view, None when it leaves no pixel to track on."""
        view, emptied_by = self.filtered(view, pose, state)
        return None if emptied_by is not None or view.sampleable_pixels() == 0 else view

    def guess(self, state: SLAMState) -> torch.Tensor:
        """The motion model's pose for the next frame of ``state``
        (:func:`~eslam.slam.tracking.trackers.motion_guess`): it holds still when either of
        the last two frames failed or the last was recovered: the velocity would then
        end or start at a guess, or be a jump back onto the track, not motion; read from
        the quality rows."""
        rows = state.tracking_quality
        after_failure = any(failed_row(row) for row in rows[-2:]) or (
            bool(rows) and recovery_of(rows[-1]) is not None
        )
        constant_velocity = self.context.config.tracking.constant_velocity
        return motion_guess(state.trajectory.poses, constant_velocity, after_failure)

    def view(self, frame: Frame) -> View:
        """``frame``'s images on the device as a tracker sees them (no filter applied)."""
        return self.images_view(*upload_frame(frame.rgb, frame.depth, self.context.device))

    def images_view(self, rgb: torch.Tensor, depth: torch.Tensor) -> View:
        """Images already on the device as a tracker sees them (no filter applied)."""
        border = self.context.config.tracking.border
        return make_view(rgb, depth, self.context.directions, border)
