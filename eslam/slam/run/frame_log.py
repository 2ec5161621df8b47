"""What a frame's tracking says in the run's log: frames without depth, failed frames
(those whose image features overruled the tracker, and by how much) and where a run of
them ends, frames the recovery found after a failed try (and how),
frames a view filter emptied, and where a stretch of degenerate views begins and ends.

:class:`FrameLogObserver` reads each :class:`~eslam.slam.run.observers.FrameDone`; the
front end and the loop only report. A resumed run picks up a degenerate stretch where
the checkpoint left it (the quality rows are saved).
"""

from __future__ import annotations

import logging

from eslam.slam.run.observers import FrameDone, RunObserverBase, RunStart
from eslam.slam.state import degenerate_row, degenerate_stretch, failed_stretch, quality_row
from eslam.slam.tracking.base import TrackingQuality


class FrameLogObserver(RunObserverBase):
    """Warnings about frames on the run's logger (module doc)."""

    def __init__(self, logger: logging.Logger) -> None:
        self.log = logger
        self._stretch = 0  # degenerate frames just before the next one
        self._lost = 0  # failed frames just before the next one

    def on_start(self, start: RunStart) -> None:
        self._stretch = degenerate_stretch(start.state.tracking_quality)
        self._lost = failed_stretch(start.state.tracking_quality)

    def on_frame(self, frame: FrameDone) -> None:
        timestamp = float("nan") if frame.frame is None else frame.frame.timestamp
        if not frame.has_depth:
            self.log.warning(
                "frame %d (timestamp %.6f) has no valid depth: skipped (pose predicted, "
                "not tracked or mapped)",
                frame.index,
                timestamp,
            )
        if frame.emptied_by is not None:
            self.log.warning(
                "frame %d: %s: not tracked, the motion model's pose is kept",
                frame.index,
                frame.emptied_by,
            )
        quality = frame.quality
        if frame.failed and quality is not None and quality.overruled:
            self.log.warning(
                "frame %d (timestamp %.6f): the map moved the camera %.1f cm from the pose"
                " its image features agree on (%.0f%% inliers there): the features' pose"
                " is kept and the frame is no keyframe",
                frame.index,
                timestamp,
                100.0 * (quality.start_shift_m or 0.0),
                100.0 * quality.inlier_fraction,
            )
        elif frame.failed:
            assert quality is not None
            self.log.warning(
                "frame %d (timestamp %.6f): tracking failed (%.0f%% inliers, residual %.1f mm):"
                " its starting pose is kept and the frame is no keyframe",
                frame.index,
                timestamp,
                100.0 * quality.inlier_fraction,
                1000.0 * quality.residual_m,
            )
        if quality is not None and quality.recovery is not None:
            self._recovered(frame.index, quality)
        self._loss(frame)
        self._degeneracy(frame.index, frame)

    def _recovered(self, index: int, quality: TrackingQuality) -> None:
        """Say how the recovery found a frame the first try failed."""
        how = {
            "start": "from the last pose held still"
            if quality.recovered_from is None
            else f"from the pose of keyframe frame {quality.recovered_from}",
            "relocalised": f"relocalised at keyframe frame {quality.recovered_from}",
        }[quality.recovery or ""]
        log = self.log.warning if quality.recovery == "relocalised" else self.log.info
        log(
            "frame %d: the first try failed; tracked %s (%.0f%% inliers, residual %.1f mm),"
            " made a keyframe",
            index,
            how,
            100.0 * quality.inlier_fraction,
            1000.0 * quality.residual_m,
        )

    def _loss(self, frame: FrameDone) -> None:
        """Log where a run of failed frames ends (the camera is tracked again)."""
        if frame.failed:
            self._lost += 1
            return
        if self._lost and frame.tracked:
            self.log.info(
                "frame %d: tracked again after %d failed frames (%d-%d)",
                frame.index,
                self._lost,
                frame.index - self._lost,
                frame.index - 1,
            )
            self._lost = 0

    def _degeneracy(self, index: int, frame: FrameDone) -> None:
        """Log where a stretch of degenerate views begins and ends (not every frame)."""
        degenerate = degenerate_row(quality_row(frame.quality))
        quality = frame.quality
        if degenerate and self._stretch == 0:
            assert quality is not None
            self.log.warning(
                "frame %d: the view pins the pose down in only %d of 6 directions (smallest"
                " normalised information %.4f): along the rest the pose follows the motion"
                " model and may drift unseen (tracking_degenerate_frames in metrics.json)",
                index,
                6 - int(quality.degenerate_directions or 0),
                quality.information,
            )
        elif not degenerate and self._stretch > 0:
            self.log.info(
                "frame %d: the view constrains the whole pose again (frames %d-%d were degenerate)",
                index,
                index - self._stretch,
                index - 1,
            )
        self._stretch = self._stretch + 1 if degenerate else 0
