"""The hybrid tracker (``tracking.method: hybrid``): the SDF tracker, then a few steps
of the rendering tracker from its pose (docs/tracking.md)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from eslam.render.renderer import SceneFieldLike
from eslam.slam.tracking.base import TrackingResult
from eslam.slam.tracking.render import RenderTracker
from eslam.slam.tracking.sdf import SdfTracker
from eslam.slam.views import View


@dataclass(frozen=True)
class HybridTracker:
    """``tracking.method: hybrid``: the SDF tracker, then a few iterations of the
    rendering tracker from its pose (the paper's loss on top of a converged start).

    A frame the SDF tracker reports as failed is not refined (it stays failed).
    """

    sdf: SdfTracker
    render: RenderTracker

    def track(
        self,
        field: SceneFieldLike,
        view: View,
        initial_pose: torch.Tensor,
        generator: torch.Generator,
    ) -> TrackingResult:
        """SDF pose, refined by the rendering tracker unless the SDF tracking failed."""
        coarse = self.sdf.track(field, view, initial_pose, generator)
        if coarse.quality is not None and coarse.quality.failed:
            return coarse
        refined = self.render.track(field, view, coarse.pose, generator)
        return TrackingResult(pose=refined.pose, loss=refined.loss, quality=coarse.quality)
