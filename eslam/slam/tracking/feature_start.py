"""A frame's starting pose from image features (``tracking.start: features``).

The SDF tracker converges from a start within about the truncation of the truth (a few
centimetres, a few degrees at room depth); the motion model's constant-velocity guess
is that close only while the camera moves smoothly and the frames come densely. Between
frames far apart in time (a stride, a real-time run that processes a fraction of the
frames) or through a jerk, the guess is often several centimetres and degrees off
(measured in docs/tracking.md, "Starting pose"), and the tracker settles on a wrong
pose or fails.

With ``start: features`` each frame's ORB features are matched to a reference image
whose pose the run has: the previous frame when it was tracked, or when it failed but
its own start came from features (it keeps that pose: the features carry the camera
from frame to frame while the map cannot confirm it, instead of holding it still),
else the latest keyframe (:class:`~eslam.slam.places.index.PlaceIndex`, shared with the
recovery's relocalisation; also when the previous frame gives no pose), else the
``start_alike`` keyframes whose images look most like the frame (the index's global
descriptor; the one most matches agree on). A rigid motion
fitted in RANSAC to the matched features' depth points
(:func:`~eslam.slam.places.index.pose_from_matches`; the reference's points placed
with its pose now) gives the starting pose: frame-to-frame visual odometry as a coarse
alignment, the SDF tracker then refining it against the map. With the previous frame
and the latest keyframe the match runs coarse to fine (``start_coarse`` features first,
the rest guided by their pose; :func:`~eslam.slam.places.index.coarse_to_fine`), with
the look-alike keyframes (far views) all with all. A frame with fewer than
``start_min_matches`` agreeing matches starts from the motion model's guess, as before.

A start that many matches agree on (``start_overrule_matches``) also checks the
tracker's answer (:meth:`FeatureStart.overrules`): when the map pulls the camera more
than ``start_overrule_shift`` from it, the map is the one in doubt (a stale or thin map
the view reaches past: in real-time replays of TUM fr1/xyz such frames passed the
tracker's tests 5-14 cm off while their features' pose was within 2.5 cm of the
truth; docs/tracking.md), and the frame keeps its features' pose and counts failed
(no keyframe). At most ``start_overrule_frames`` in a row: features alone drift, and
the map must be able to take the camera back.

The previous frame's features are this component's state (``state.components``,
:data:`COMPONENT`): checkpointed and rolled back with the frame, so a resumed run
starts each frame as the uninterrupted one does (the fit's samples are drawn with the
frame index as seed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from eslam.slam.places.features import Features
from eslam.slam.places.index import Place, Places, describe, pose_from_matches
from eslam.slam.state import SLAMState, overruled_row, overruled_stretch
from eslam.slam.tracking.base import TrackingQuality
from eslam.types import Frame

COMPONENT = "feature_start"
"""The key of this component's state in ``state.components``: the last tracked
frame's index and its features (``frame`` and :data:`FEATURES`), how many
frames started from where (``starts``: :data:`STARTS` -> count; metrics.json's
``tracking_starts``). The overruled frames are read from the run's quality rows."""

FEATURES = ("pixels", "descriptors", "points")
"""The fields of :class:`~eslam.slam.places.features.Features` kept, in its order."""

STARTS = ("previous_frame", "keyframe", "alike_keyframe", "motion_model")
"""Where a frame's start came from: features matched to the previous frame's, to the
latest keyframe's, to those of a keyframe that looks alike, or (too few agreed) the
motion model's guess."""


@dataclass(frozen=True)
class OverruleRule:
    """When a start of features overrules the tracker (module doc).

    Attributes:
        matches: agreeing matches the start needs (``tracking.start_overrule_matches``).
        shift: metres the tracker must move the camera centre from it
            (``tracking.start_overrule_shift``).
        frames: the most frames in a row (``tracking.start_overrule_frames``).
    """

    matches: int
    shift: float
    frames: int


@dataclass(frozen=True, eq=False)
class FeatureStartResult:
    """A starting pose from features.

    Attributes:
        pose: (4, 4) float64 camera-to-world, on the CPU.
        reference: the frame index of the image it was matched to.
        inliers: the matches that agree on it.
        source: which image that was (:data:`STARTS`, not ``motion_model``).
    """

    pose: torch.Tensor
    reference: int
    inliers: int
    source: str = "previous_frame"


class FeatureStart:
    """The starting pose of the module doc.

    Args:
        places: the run's place index.
        min_matches: matches that must agree on the pose (RANSAC inliers within 3 cm).
        overrule: the rule by which a start overrules the tracker (None: never).
        alike: keyframes that look most like the frame tried after the latest one
            (``tracking.start_alike``; 0: none).
        coarse: features of the frame matched to the previous frame's and the latest
            keyframe's first, for a rough pose that guides the rest
            (``tracking.start_coarse``; 0: all at once).
    """

    def __init__(
        self,
        places: Places,
        min_matches: int,
        overrule: OverruleRule | None = None,
        alike: int = 0,
        coarse: int = 0,
    ) -> None:
        self.places = places
        self.min_matches = min_matches
        self.overrule = overrule
        self.alike = alike
        self.coarse = coarse

    def describe(self, frame: Frame, state: SLAMState) -> Place:
        """``frame`` as a place (global descriptor and ORB features with depth)."""
        return describe(frame.rgb, frame.depth, state.keyframes, self.places.orb)

    def start(self, query: Place, state: SLAMState) -> FeatureStartResult | None:
        """The next frame's pose from its features ``query`` matched to the previous
        frame's (when it was tracked), else to the latest keyframe's, else to those of
        the ``alike`` keyframes that look most like it (the one most matches agree on);
        None when none gives ``min_matches`` agreeing matches. Counts where the start
        came from."""
        found = self.matched(query, state)
        how = "motion_model" if found is None else found.source
        starts = state.component(COMPONENT).setdefault("starts", dict.fromkeys(STARTS, 0))
        starts[how] = starts.get(how, 0) + 1  # a run saved before a source existed lacks it
        return found

    def matched(self, query: Place, state: SLAMState) -> FeatureStartResult | None:
        """:meth:`start`'s pose, not counted."""
        index = state.next_frame
        previous = state.components.get(COMPONENT, {})
        tried = previous.get("frame") == index - 1
        if tried:
            reference = Features(*(previous[key].numpy() for key in FEATURES))
            pose = state.trajectory.poses[index - 1]
            found = pose_from_matches(
                query.features, reference, pose, self.min_matches, index, self.coarse
            )
            if found is not None:
                pose = torch.from_numpy(found.pose)
                return FeatureStartResult(pose, index - 1, found.inliers, "previous_frame")
        store = state.keyframes
        if len(store) == 0:
            return None
        frames = store.frame_indices
        places = self.places.of(store)
        latest = max(range(len(frames)), key=frames.__getitem__)
        # unless the latest keyframe is the previous frame, matched above
        if not (tried and frames[latest] == index - 1):
            match = places.locate(query, latest, self.min_matches, index, self.coarse)
            if match is not None:  # counted as the previous frame's when it is that frame
                pose, reference = torch.from_numpy(match.pose), frames[latest]
                source = "previous_frame" if reference == index - 1 else "keyframe"
                return FeatureStartResult(pose, reference, match.inliers, source)
        best = None
        for k, _ in places.alike(query, self.alike + 1) if self.alike else []:
            if k == latest:
                continue
            match = places.locate(query, k, self.min_matches, seed=index)
            if match is not None and (best is None or match.inliers > best.inliers):
                best = match
        if best is None:
            return None
        pose = torch.from_numpy(best.pose)
        return FeatureStartResult(pose, frames[best.keyframe], best.inliers, "alike_keyframe")

    def overrules(
        self, found: FeatureStartResult, quality: TrackingQuality, state: SLAMState
    ) -> bool:
        """Whether the start ``found`` overrules the tracker's answer, judged
        ``quality`` with its ``start_shift_m`` (the module doc's rule: a passed frame
        whose start ``overrule.matches`` agree on, moved more than ``overrule.shift``,
        fewer than ``overrule.frames`` frames in a row before it, read from the run's
        quality rows)."""
        rule = self.overrule
        shift = quality.start_shift_m
        return (
            rule is not None
            and not quality.failed
            and shift is not None
            and found.inliers >= rule.matches
            and shift > rule.shift
            and overruled_stretch(state.tracking_quality) < rule.frames
        )

    def remember(self, query: Place, state: SLAMState) -> None:
        """Keep ``query``, the features of the frame just tracked (or failed with its
        pose from features), as the next frame's reference (in ``state.components``)."""
        features = query.features
        state.component(COMPONENT).update(
            frame=state.next_frame,
            **{
                key: torch.from_numpy(np.ascontiguousarray(getattr(features, key)))
                for key in FEATURES
            },
        )


def start_shift(found: FeatureStartResult, pose: torch.Tensor) -> float:
    """Metres between the camera centres of the start ``found`` and the tracker's
    ``pose`` (reads the device once)."""
    moved = pose.detach().to("cpu", torch.float64)[:3, 3] - found.pose[:3, 3]
    return float(torch.linalg.vector_norm(moved))


def start_metrics(state: SLAMState) -> dict:
    """metrics.json's ``tracking_starts`` (frames by where their start came from,
    :data:`STARTS`) and ``tracking_overruled`` (frames whose features overruled the
    tracker) when the run starts frames from features, else nothing."""
    starts = state.components.get(COMPONENT, {}).get("starts")
    if starts is None:
        return {}
    overruled = sum(map(overruled_row, state.tracking_quality))
    return {"tracking_starts": dict(starts), "tracking_overruled": overruled}
