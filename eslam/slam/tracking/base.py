"""What every tracker shares: its answer (:class:`TrackingResult`), its judgement of a
frame (:class:`TrackingQuality`) and the protocol a tracker implements
(:class:`Tracker`). Trackers are registered by name in
:data:`eslam.slam.tracking.trackers.TRACKERS`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch

from eslam.render.renderer import SceneFieldLike
from eslam.slam.views import View


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
    """

    iterations: int
    inlier_fraction: float
    residual_m: float
    failed: bool
    information: float = float("nan")
    degenerate_directions: int | None = None


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
