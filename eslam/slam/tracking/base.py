"""What every tracker shares: its answer (:class:`TrackingResult`), its judgement of a
frame (:class:`TrackingQuality`), the protocol a tracker implements (:class:`Tracker`)
and how the run takes an answer (:func:`judged`). Trackers are registered by name in
:data:`eslam.slam.tracking.trackers.TRACKERS`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import torch

from eslam.render.renderer import SceneFieldLike
from eslam.slam.views import View

Recovery = Literal["start", "relocalised"]
"""How the front end recovered a frame its tracker failed
(:mod:`eslam.slam.tracking.recovery`): tracked from another starting pose, or
relocalised at a keyframe that looks alike."""

RECOVERIES: tuple[Recovery, ...] = ("start", "relocalised")
"""Every :data:`Recovery`, in the order they are tried."""


@dataclass(frozen=True)
class TrackingQuality:
    """How well a frame was tracked (trackers that can tell).

    Attributes:
        iterations: solver iterations taken.
        inlier_fraction: share of the frame's points that fit the map.
        residual_m: robust RMS residual of the inliers, metres.
        failed: the tracker judged the pose unusable (the loop keeps the motion model's
            pose and makes the frame no keyframe).
        information: the smallest eigenvalue of the points' normalised information at the
            final pose (about 1 along a direction every point's normal sees, 0 along one
            no point constrains: sliding along a wall); NaN where not computed.
        degenerate_directions: pose directions below the tracker's degeneracy threshold
            (along them the pose is the motion model's, not measured); None when the
            tracker has no such test or it is off.
        recovery: how the front end recovered the frame after the tracker failed it
            from the motion model's guess (the figures above are the recovered try's),
            None when the first try passed (or nothing recovered it).
        recovered_from: the frame index of the keyframe whose pose the recovered try
            started from (``start`` from a keyframe, ``relocalised``), else None.
        start_matches: the feature matches that agreed on the frame's start
            (``tracking.start: features``), None when it started from the motion model.
        start_shift_m: metres the tracker moved the camera centre from that start
            (frames the tracker passed), else None.
        overruled: the start overruled the tracker (the map pulled the camera more than
            ``tracking.start_overrule_shift`` from it): the frame failed and keeps the
            features' pose (:mod:`eslam.slam.tracking.feature_start`).
    """

    iterations: int
    inlier_fraction: float
    residual_m: float
    failed: bool
    information: float = float("nan")
    degenerate_directions: int | None = None
    recovery: Recovery | None = None
    recovered_from: int | None = None
    start_matches: int | None = None
    start_shift_m: float | None = None
    overruled: bool = False


@dataclass(frozen=True, eq=False)
class TrackingResult:
    """Outcome of tracking one frame.

    Attributes:
        pose: (4, 4) float32 camera-to-world pose with the lowest loss.
        loss: 0-d tensor on the compute device, that lowest loss (read it with
            ``float()`` between frames, not inside the iterations).
        quality: the tracker's own judgement, or None (the rendering tracker has none).
    """

    pose: torch.Tensor
    loss: torch.Tensor
    quality: TrackingQuality | None = None


class Tracker(Protocol):
    """Estimates one frame's camera-to-world pose against the frozen map."""

    def track(
        self,
        field: SceneFieldLike,
        view: View,
        initial_pose: torch.Tensor,
        generator: torch.Generator,
    ) -> TrackingResult:
        """Pose of ``view`` (the frame's images on the device), starting at ``initial_pose``."""
        ...


def judged(
    result: TrackingResult, guess: torch.Tensor
) -> tuple[torch.Tensor, TrackingQuality | None]:
    """A tracker's answer as the run takes it: (pose, quality). A non-finite pose is a
    failure; a failed frame keeps ``guess`` (reads the device once)."""
    quality = result.quality
    if not bool(torch.isfinite(result.pose).all()):
        quality = non_finite_quality(quality)
    pose = guess if quality is not None and quality.failed else result.pose
    return pose, quality


def non_finite_quality(quality: TrackingQuality | None) -> TrackingQuality:
    """The judgement of a frame whose tracker returned a non-finite pose: failed."""
    iterations = 0 if quality is None else quality.iterations
    return TrackingQuality(iterations, 0.0, float("inf"), failed=True)
