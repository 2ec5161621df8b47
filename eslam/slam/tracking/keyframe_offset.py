"""The tracker's frame and the mapper's: frames after a keyframe follow the mapper's pose
of it (``tracking.keyframe_offset``; docs/tracking.md, "Keyframe offset").

Two estimators place the camera on the same map: the tracker (the SDF tracker's fit of
the depth points to the map's TSDF, or the rendering loss, or both) and the mapping
call (the rendering loss over the window's keyframes, poses and map optimised
together). Their optima differ by a few millimetres. A keyframe's pose is the
mapper's, the frames tracked after it are the tracker's, so every keyframe left a step
in the trajectory: on TUM fr1/xyz the frame-to-frame error of the step into the frame
after a keyframe was half again that of the others (docs/results.md).

After each mapping call the front end tracks the call's newest keyframe again, from the
pose the call gave it, on the map the call left: the tracker's pose T_k of it. The
offset

    D = T'_k T_k^-1        (T'_k: the mapper's pose of keyframe k)

maps the tracker's answer into the mapper's frame, and every frame tracked on that map
takes D T_f instead of T_f, until the next call gives a new offset. A re-track the
tracker judges failed leaves no offset (the identity) until the next call; a tracker
without a judgement (``render``) is taken at its word, as on any frame. The offset is
this component's state (``state.components``, :data:`COMPONENT`), checkpointed and
rolled back with the frame; the keyframe it was measured on comes from the back end
(``components["back_end"]["mapped"]``: the frame index of the newest keyframe whose
call completed, also with mapping beside the tracker).
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from eslam.geometry.pose import invert, pose_distance
from eslam.slam.context import RunContext
from eslam.slam.state import SLAMState
from eslam.slam.tracking.base import Tracker, judged
from eslam.slam.views import View

COMPONENT = "keyframe_offset"
"""The key of this component's state in ``state.components``: ``keyframe`` (the frame
index of the keyframe the offset was measured on), ``offset`` (D, 16 numbers row by
row, or None), ``measured`` (offsets measured) and ``translation_mm`` (the sum of the
distances between the two camera centres, for metrics.json)."""

MAPPED = "mapped"
"""The back end's entry (``components["back_end"]``) naming the newest keyframe whose
mapping call completed (its frame index)."""

ImagesView = Callable[[torch.Tensor, torch.Tensor], View]
"""The front end's view of colour and depth images on the device (its border applied)."""

Restrict = Callable[[View, torch.Tensor, SLAMState], View | None]
"""The front end's view filters: a view restricted as a frame tracked from a pose is
(None when they leave nothing)."""


def keyframe_offset(mapped: torch.Tensor, tracked: torch.Tensor) -> torch.Tensor:
    """D = T'_k T_k^-1 (module doc): the left-multiplied correction taking the tracker's
    pose ``tracked`` of a keyframe to the mapper's ``mapped`` ((..., 4, 4) each)."""
    return mapped @ invert(tracked)


class KeyframeOffset:
    """The offset of the module doc, for one run.

    Args:
        context: the run.
        tracker: the front end's tracker.
        images_view: the front end's view of a keyframe's images.
        restrict: the front end's view filters.
    """

    def __init__(
        self, context: RunContext, tracker: Tracker, images_view: ImagesView, restrict: Restrict
    ) -> None:
        self.context = context
        self.tracker = tracker
        self.images_view = images_view
        self.restrict = restrict
        # D on the device, built once per measurement: no host-to-device copy per frame
        self._device_offset: tuple[tuple, torch.Tensor] | None = None

    def update(self, state: SLAMState) -> None:
        """Measure the offset on the newest mapped keyframe when a call completed since
        the last measurement (one tracking of that keyframe; nothing otherwise)."""
        mapped = state.component("back_end").get(MAPPED)
        own = state.component(COMPONENT)
        if mapped is None or own.get("keyframe") == mapped or state.field is None:
            return
        own["keyframe"] = mapped
        own["offset"] = None
        store = state.keyframes
        k = store.frame_indices.index(mapped)
        device = self.context.device
        pose = state.trajectory.poses[mapped].to(device)
        whole = self.images_view(store.rgb(k, device), store.depth(k, device))
        view = self.restrict(whole, pose, state)
        if view is None:
            return
        result = self.tracker.track(state.field, view, pose, state.generator)
        tracked, quality = judged(result, pose)
        if quality is not None and quality.failed:
            self.context.logger.info(
                "keyframe offset: keyframe frame %d fails to track on its own map; "
                "frames keep the tracker's poses until the next mapping call",
                mapped,
            )
            return
        mapped_pose, tracked = pose.double().cpu(), tracked.double().cpu()  # once a call
        offset = keyframe_offset(mapped_pose, tracked)
        translation, _ = pose_distance(mapped_pose, tracked)  # between the camera centres
        own["offset"] = offset.flatten().tolist()
        own["measured"] = own.get("measured", 0) + 1
        own["translation_mm"] = own.get("translation_mm", 0.0) + 1000.0 * float(translation)

    def apply(self, pose: torch.Tensor, state: SLAMState) -> torch.Tensor:
        """The tracker's ``pose`` of a frame in the mapper's frame: D ``pose``."""
        own = state.component(COMPONENT)
        offset = own.get("offset")
        if offset is None:
            return pose
        key = (own.get("keyframe"), own.get("measured"), pose.device, pose.dtype)
        if self._device_offset is None or self._device_offset[0] != key:
            matrix = torch.tensor(offset, dtype=torch.float64).reshape(4, 4).to(pose)
            self._device_offset = (key, matrix)
        return self._device_offset[1] @ pose


def offset_metrics(state: SLAMState) -> dict:
    """metrics.json's ``tracking_keyframe_offsets`` (offsets measured) and
    ``tracking_keyframe_offset_mm`` (their mean translation) when the run measures them,
    else nothing."""
    own = state.components.get(COMPONENT)
    if not own or not own.get("measured"):
        return {}
    measured = own["measured"]
    return {
        "tracking_keyframe_offsets": measured,
        "tracking_keyframe_offset_mm": own["translation_mm"] / measured,
    }
