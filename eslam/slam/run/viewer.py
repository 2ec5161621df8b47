"""The live viewer as a run observer: what is shown and when (docs/live.md).

:class:`ViewerObserver` turns the run's events into host arrays: the camera (pose,
intrinsics, the frame's colour and depth), the trajectory so far (estimate, and ground
truth when the frame had it), a view rendered from the map every ``viewer.render_every``
frames (:func:`eslam.render.surface.render_novel_view`), the mesh every
``viewer.mesh_every`` keyframes and at the end, and per-frame scalars. How they are
shown is a :class:`ViewerSink`'s job (the rerun one: :mod:`eslam.viz.rerun_viewer`), so
this module needs no viewer library.

The observer only reads the run's state: renders and meshes run without gradients, draw
no random numbers (deterministic samples) and leave the field, poses and generator as
they were. It pays for its own host copies and its renders and meshes (the run waits
for them); without a viewer nothing here is imported or called.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Protocol

import numpy as np
import torch

from eslam.config import ViewerConfig
from eslam.mesh.extract import extract_mesh
from eslam.render.surface import render_novel_view
from eslam.slam.run.observers import FrameDone, MappingDone, RunEnd, RunObserverBase, RunStart
from eslam.types import Intrinsics, TriangleMesh


class ViewerSink(Protocol):
    """Where the viewer's arrays go; ``index`` is the frame they belong to (the time)."""

    def show_camera(
        self,
        index: int,
        intrinsics: Intrinsics,
        pose: np.ndarray,
        rgb: np.ndarray | None,
        depth: np.ndarray | None,
    ) -> None:
        """The camera: (4, 4) camera-to-world ``pose``, its (H, W, 3) uint8 colour and
        (H, W) float32 depth (metres, 0 = none) images, or None when the frame has none."""
        ...

    def show_trajectory(
        self, index: int, estimated: np.ndarray, ground_truth: np.ndarray | None
    ) -> None:
        """Camera centres so far: (N, 3) estimated, (M, 3) ground truth or None."""
        ...

    def show_loops(self, index: int, segments: np.ndarray) -> None:
        """The pose graph's loop edges as of frame ``index``: (L, 2, 3) pairs of camera
        centres (estimated) joined by a loop (replaces those shown before)."""
        ...

    def show_rendered(
        self, index: int, intrinsics: Intrinsics, depth: np.ndarray, rgb: np.ndarray
    ) -> None:
        """The map rendered at frame ``index``'s pose: (h, w) depth (metres, 0 = nothing
        hit) and (h, w, 3) uint8 colour, with the render camera's ``intrinsics``."""
        ...

    def show_mesh(self, index: int, mesh: TriangleMesh) -> None:
        """The map's mesh as of frame ``index`` (replaces the one shown before)."""
        ...

    def show_scalars(self, index: int, values: Mapping[str, float]) -> None:
        """Named numbers of frame ``index`` (plotted over frames)."""
        ...

    def close(self, complete: bool) -> None:
        """The run ended (``complete``: the stream ended; else it stopped or failed)."""
        ...

    def discard(self) -> None:
        """The run never started (bad input before its first frame): keep nothing."""
        ...


def loop_segments(edges: list, estimated: np.ndarray) -> np.ndarray:
    """(L, 2, 3) the camera centres ``estimated`` (N, 3) of each loop edge's two frames
    (loops.json's edges: [frame a, frame b, relative pose...]); edges of frames past the
    trajectory are left out."""
    pairs = [(int(e[0]), int(e[1])) for e in edges if max(e[0], e[1]) < len(estimated)]
    if not pairs:
        return np.zeros((0, 2, 3))
    return np.stack([estimated[[a, b]] for a, b in pairs])


def frame_scalars(done: FrameDone) -> dict[str, float]:
    """The numbers plotted per frame: tracking and mapping time (ms), the frames of the
    stream skipped so far (a real-time run's drops: the frame's position in its stream
    minus its position in the run; 0 otherwise) and, from trackers that judge themselves,
    the inlier share, residual (mm) and smallest normalised information (near 0: a
    degenerate view). One entry per plot."""
    values = {
        "time/tracking_ms": 1000.0 * done.tracking_s,
        "time/mapping_ms": 1000.0 * done.mapping_s,
    }
    if done.frame is not None:
        values["stream/dropped_frames"] = float(max(done.frame.index - done.index, 0))
    if done.quality is not None:
        values["tracking/inlier_fraction"] = float(done.quality.inlier_fraction)
        values["tracking/residual_mm"] = 1000.0 * float(done.quality.residual_m)
        if math.isfinite(done.quality.information):
            values["tracking/information"] = float(done.quality.information)
    return values


def render_intrinsics(intrinsics: Intrinsics, downscale: int) -> Intrinsics:
    """The camera of a render at 1/``downscale`` of the width and height (at least 1 pixel)."""
    if downscale == 1:
        return intrinsics
    width = max(1, intrinsics.width // downscale)
    height = max(1, intrinsics.height // downscale)
    return intrinsics.scaled(width, height)


def centres(poses: np.ndarray) -> np.ndarray:
    """(K, 3) camera centres of the finite poses among (N, 4, 4) (missing ones left out)."""
    finite = np.isfinite(poses).all(axis=(1, 2))
    return poses[finite, :3, 3]


class ViewerObserver(RunObserverBase):
    """Shows a run on ``sink`` as it goes (module doc).

    Args:
        sink: where the arrays go.
        settings: how often to render and to mesh (``viewer`` section of the config).
    """

    def __init__(self, sink: ViewerSink, settings: ViewerConfig) -> None:
        self.sink = sink
        self.settings = settings
        self.start: RunStart | None = None
        self.keyframes = 0
        self.last_index = -1
        self.loops_shown = 0
        self.closed = False

    def on_start(self, start: RunStart) -> None:
        self.start = start
        self.keyframes = len(start.state.keyframes)

    def on_frame(self, frame: FrameDone) -> None:
        if self.start is None:
            return
        state = self.start.state
        index = frame.index
        self.last_index = index
        pose = frame.pose.detach().to("cpu", torch.float64).numpy()
        image = frame.frame
        self.sink.show_camera(
            index,
            state.keyframes.intrinsics,
            pose,
            None if image is None else image.rgb,
            None if image is None else image.depth,
        )
        self._show_trajectory(index)
        self.sink.show_scalars(index, frame_scalars(frame))
        every = self.settings.render_every
        if every > 0 and index % every == 0 and state.field is not None:
            self._render(index, frame.pose)
        if frame.mapped:
            self.keyframes += 1
            every = self.settings.mesh_every
            if every > 0 and (self.keyframes - 1) % every == 0:
                self._mesh(index)

    def on_mapping(self, mapping: MappingDone) -> None:
        if self.start is not None:
            self.sink.show_scalars(mapping.index, {"mapping/loss": float(mapping.loss)})

    def on_finish(self, end: RunEnd) -> None:
        """The final trajectory (mapping refined it) and mesh, then close the sink."""
        try:
            if self.start is not None and self.last_index >= 0:
                self._show_trajectory(self.last_index)
                if self.settings.mesh_every > 0:
                    self._mesh(self.last_index)
        finally:
            self._close(end.complete)

    def on_failure(self, error: BaseException, frames: int) -> None:
        self._close(False)

    def release(self) -> None:
        """After the run, however it went: close the sink if the run did not (a run that
        never started, e.g. stopped by bad input, is discarded: no recording is kept)."""
        if self.closed:
            return
        if self.start is None:
            self.closed = True
            self.sink.discard()
        else:
            self._close(False)

    def _close(self, complete: bool) -> None:
        if not self.closed:
            self.closed = True
            self.sink.close(complete)

    def _show_trajectory(self, index: int) -> None:
        """The trajectory (corrected by loop closure, refined by mapping: all of it is
        sent each time) and, with loop closure on, its loop edges when they changed."""
        state = self.start.state
        trajectory = state.trajectory
        estimated = centres(trajectory.poses.detach().to("cpu", torch.float64).numpy())
        gt = trajectory.gt_poses()
        self.sink.show_trajectory(index, estimated, None if gt is None else centres(gt))
        edges = state.components.get("loops", {}).get("edges", [])
        if len(edges) != self.loops_shown:
            self.loops_shown = len(edges)
            self.sink.show_loops(index, loop_segments(edges, estimated))

    def _render(self, index: int, pose: torch.Tensor) -> None:
        start = self.start
        intrinsics = render_intrinsics(
            start.state.keyframes.intrinsics, self.settings.render_downscale
        )
        depth, rgb = render_novel_view(
            start.state.field, intrinsics, pose.detach(), start.config.render
        )
        colour = np.round(255.0 * rgb.clamp(0.0, 1.0).cpu().numpy()).astype(np.uint8)
        self.sink.show_rendered(index, intrinsics, depth.cpu().numpy(), colour)

    def _mesh(self, index: int) -> None:
        state = self.start.state
        if state.field is None or len(state.keyframes) == 0:
            return
        mesh = extract_mesh(state.field, self.settings.mesh_resolution, state.observed_views())
        self.sink.show_mesh(index, mesh)
