"""The rerun viewer: a :class:`~eslam.slam.run.viewer.ViewerSink` that logs to rerun (docs/live.md).

rerun-sdk (the ``[viewer]`` extra, pinned to 0.41: its API changes every minor release)
is imported only when a viewer is asked for. One recording stream per run, with any of
three sinks at once:

- ``spawn``: a rerun viewer started on this machine (``rerun`` on the PATH, installed
  with the extra), fed over gRPC on port ``grpc_port``;
- ``serve``: a gRPC server on ``grpc_port`` plus rerun's web viewer on ``web_port``, for
  a browser on another machine (forward both ports);
- ``save``: an .rrd file, recorded under a temporary name beside it and moved into place
  when the run ends (however it ends), so the file is either absent or complete.

What is logged, on the ``frame`` timeline (entity paths):

- ``world/camera``: Transform3D (camera-to-world) and, under it, ``image``: Pinhole
  (OpenCV axes) with ``image/rgb`` (JPEG) and ``image/depth`` (uint16 millimetres);
- ``world/trajectory/estimated`` and ``world/trajectory/ground_truth``: LineStrips3D;
- ``world/mesh``: Mesh3D with vertex colours, replaced whole on each refresh;
- ``rendered/rgb`` and ``rendered/depth``: the map rendered at the current pose;
- ``scalars/<name>``: Scalars (``mapping/loss``, ``time/tracking_ms``, ...).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.atomic import atomic_path
from eslam.errors import ConfigError
from eslam.types import Intrinsics, TriangleMesh
from eslam.viz.depth_images import depth_millimetres

log = logging.getLogger("eslam")

TESTED_RERUN = "0.41"
"""The rerun-sdk minor version this module is written and tested against."""
INSTALL = 'pip install "eslam[viewer]"'
"""The install line named by every error about a missing or wrong rerun."""
JPEG_QUALITY = 85
"""JPEG quality of the logged colour images (a tenth of the raw size at 640x480)."""
TIMELINE = "frame"
"""The timeline everything is logged on: the frame's index in the run."""
FLUSH_TIMEOUT_S = 60.0
"""Longest wait for the stream to drain when the run ends, seconds."""
ESTIMATE_COLOUR = (230, 60, 60)
GROUND_TRUTH_COLOUR = (40, 40, 40)
LOOP_COLOUR = (40, 160, 240)
"""Loop edges: the two camera centres each accepted loop joins."""


def import_rerun():
    """The rerun module, or ConfigError naming the extra to install (or the pinned version)."""
    try:
        import rerun
    except ImportError:
        raise ConfigError(f"the live viewer needs rerun-sdk {TESTED_RERUN}: {INSTALL}") from None
    version = getattr(rerun, "__version__", "unknown")
    if not version.startswith(f"{TESTED_RERUN}."):
        raise ConfigError(
            f"rerun-sdk {version} is installed, but eslam's viewer is written for "
            f"{TESTED_RERUN} (rerun's API changes every minor release): {INSTALL}"
        )
    return rerun


@dataclass(frozen=True)
class ViewerOutputs:
    """Where a run's viewer stream goes (any combination; at least one).

    Attributes:
        spawn: start a rerun viewer on this machine.
        serve: serve the stream and rerun's web viewer for a browser elsewhere.
        save: record to this .rrd file.
        grpc_port: port of the gRPC stream (spawned viewer or served).
        web_port: port of the served web viewer.
    """

    spawn: bool = False
    serve: bool = False
    save: Path | None = None
    grpc_port: int = 9876
    web_port: int = 9090

    def __post_init__(self) -> None:
        if not (self.spawn or self.serve or self.save is not None):
            raise ValueError("a viewer needs somewhere to go: spawn, serve or save")
        if self.spawn and self.serve:
            raise ValueError("spawn a viewer or serve one, not both")


class RerunSink:
    """Logs a run to a rerun recording stream (module doc); :func:`open_rerun_sink` makes one.

    Args:
        rerun: the rerun module.
        recording: the run's recording stream, its sinks set.
        files: the open temporary .rrd file (closed, i.e. published, by :meth:`close`).
    """

    def __init__(self, rerun, recording, files: contextlib.ExitStack) -> None:
        self.rr = rerun
        self.recording = recording
        self.files = files
        self.pinhole: Intrinsics | None = None
        self.rendered_pinhole: Intrinsics | None = None

    def _at(self, index: int) -> None:
        self.recording.set_time(TIMELINE, sequence=int(index))

    def _pinhole(self, intrinsics: Intrinsics):
        return self.rr.Pinhole(
            image_from_camera=intrinsics.matrix(),
            resolution=[intrinsics.width, intrinsics.height],
            camera_xyz=self.rr.ViewCoordinates.RDF,
        )

    def show_camera(
        self,
        index: int,
        intrinsics: Intrinsics,
        pose: np.ndarray,
        rgb: np.ndarray | None,
        depth: np.ndarray | None,
    ) -> None:
        rr, log = self.rr, self.recording.log
        self._at(index)
        if intrinsics != self.pinhole:
            log("world/camera/image", self._pinhole(intrinsics))
            self.pinhole = intrinsics
        log("world/camera", rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))
        if rgb is not None:
            log("world/camera/image/rgb", rr.Image(rgb).compress(jpeg_quality=JPEG_QUALITY))
        if depth is not None:
            log("world/camera/image/depth", millimetre_depth(rr, depth))

    def show_trajectory(
        self, index: int, estimated: np.ndarray, ground_truth: np.ndarray | None
    ) -> None:
        rr, log = self.rr, self.recording.log
        self._at(index)
        log("world/trajectory/estimated", rr.LineStrips3D([estimated], colors=[ESTIMATE_COLOUR]))
        if ground_truth is not None and len(ground_truth):
            log(
                "world/trajectory/ground_truth",
                rr.LineStrips3D([ground_truth], colors=[GROUND_TRUTH_COLOUR]),
            )

    def show_loops(self, index: int, segments: np.ndarray) -> None:
        rr = self.rr
        self._at(index)
        self.recording.log("world/loops", rr.LineStrips3D(list(segments), colors=[LOOP_COLOUR]))

    def show_rendered(
        self, index: int, intrinsics: Intrinsics, depth: np.ndarray, rgb: np.ndarray
    ) -> None:
        rr, log = self.rr, self.recording.log
        self._at(index)
        log("rendered/rgb", rr.Image(rgb).compress(jpeg_quality=JPEG_QUALITY))
        log("rendered/depth", millimetre_depth(rr, depth))

    def show_mesh(self, index: int, mesh: TriangleMesh) -> None:
        self._at(index)
        self.recording.log(
            "world/mesh",
            self.rr.Mesh3D(
                vertex_positions=mesh.vertices.astype(np.float32),
                triangle_indices=mesh.faces.astype(np.uint32),
                vertex_colors=mesh.colours,
            ),
        )

    def show_scalars(self, index: int, values: Mapping[str, float]) -> None:
        self._at(index)
        for name, value in values.items():
            self.recording.log(f"scalars/{name}", self.rr.Scalars(float(value)))

    def discard(self) -> None:
        """The run never started: stop streaming and write no file."""
        try:
            self.recording.disconnect()
        finally:
            never = RuntimeError("the run never started")
            self.files.__exit__(RuntimeError, never, None)  # removes the temporary .rrd

    def close(self, complete: bool) -> None:
        """Flush the stream; publish the .rrd (complete or not: it holds what happened).

        A viewer that went away (closed, or never able to start) costs its stream, never
        the run: a warning says so.
        """
        try:
            self.recording.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as error:
            log.warning("the viewer's stream was lost (the run is unaffected): %s", error)
        finally:
            try:
                self.recording.disconnect()
            finally:
                self.files.close()


def millimetre_depth(rerun, depth: np.ndarray):
    """A rerun DepthImage of ``depth`` (metres) as uint16 millimetres (half the bytes of
    float32, and the sensors' own precision)."""
    return rerun.DepthImage(depth_millimetres(depth), meter=1000.0)


def has_display(environment: Mapping[str, str]) -> bool:
    """Whether a window can open on Linux: an X11 or Wayland display is set."""
    return bool(environment.get("DISPLAY") or environment.get("WAYLAND_DISPLAY"))


def open_rerun_sink(name: str, outputs: ViewerOutputs, say=print) -> RerunSink:
    """A :class:`RerunSink` for the run ``name`` streaming to ``outputs``.

    Args:
        name: the recording's name (the run folder's name).
        say: where the served viewer's address is told (a line of text).

    Raises:
        ConfigError: rerun is missing or of another version, or a port cannot be used.
    """
    if outputs.spawn and sys.platform.startswith("linux") and not has_display(os.environ):
        raise ConfigError(
            "--viewer rerun opens a window, but there is no display (DISPLAY and "
            "WAYLAND_DISPLAY are unset): use --viewer rerun-web and a browser, or "
            "--viewer-save FILE.rrd and open it later with `rerun FILE.rrd`"
        )
    rr = import_rerun()
    recording = rr.RecordingStream("eslam", recording_id=f"{name}-{uuid.uuid4().hex[:8]}")
    files = contextlib.ExitStack()
    sinks = []
    try:
        if outputs.save is not None:
            sinks.append(rr.FileSink(files.enter_context(atomic_path(outputs.save))))
        if outputs.spawn:
            rr.spawn(port=outputs.grpc_port, connect=False, recording=recording)
            sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{outputs.grpc_port}/proxy"))
        if outputs.serve:
            server = rr.GrpcServerSink(port=outputs.grpc_port, server_memory_limit="25%")
            sinks.append(server)
            url = f"rerun+http://localhost:{outputs.grpc_port}/proxy"
        recording.set_sinks(*sinks)
        if outputs.serve:
            rr.serve_web_viewer(web_port=outputs.web_port, open_browser=False, connect_to=url)
            say(
                f"viewer: open http://localhost:{outputs.web_port}/?url={url} "
                f"(from another machine: forward ports {outputs.web_port} and "
                f"{outputs.grpc_port}, e.g. ssh -L {outputs.web_port}:localhost:"
                f"{outputs.web_port} -L {outputs.grpc_port}:localhost:{outputs.grpc_port})"
            )
    except (OSError, RuntimeError) as error:
        files.__exit__(*sys.exc_info())  # the temporary .rrd is removed, nothing published
        raise ConfigError(f"the rerun viewer could not start: {error}") from None
    return RerunSink(rr, recording, files)
