"""The run writer: the run folder's files, as a run observer.

Every ``output.checkpoint_every`` frames, on a failure and at the end it writes map.pt
(everything needed to resume), trajectory.txt / trajectory_gt.txt (the frames so far)
and timings.json; on a failure and at the end also metrics.json (so ``eslam eval``
scores an interrupted run's frames too) and, when the stream ended, mesh.ply.
Every file is written atomically, so a crash leaves the last complete version. A
checkpoint that cannot be written (disk full, read-only) stops the run with a
:class:`~eslam.errors.RunStopped` that counts the frames of the last checkpoint that
was written (the earlier map.pt is intact), so `eslam resume` continues from there.
Nothing is saved before the first frame with valid depth (no keyframe yet): nothing
was learnt, the poses are only predictions, and a resume must start at frame 0.

metrics.json is merged, never clobbered, when the run resumed and added no frame (a
finished run resumed again): the keys ``eslam eval`` added still describe the same
frames and mesh, so they are kept. A run that processed frames since (or a new run)
writes only its own keys: earlier evaluation keys would describe another map.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from eslam.config import ESLAMConfig
from eslam.data.realtime import LatestFrameReader
from eslam.errors import OutputError, RunStopped
from eslam.evaluate.trajectory import absolute_trajectory_error, relative_pose_error
from eslam.io.run_dir import RunDirectory, write_json
from eslam.io.trajectory import write_tum_trajectory
from eslam.slam.loops.closer import COMPONENT as LOOPS
from eslam.slam.loops.closer import loop_metrics
from eslam.slam.mapping.concurrent_mapping import concurrency_metrics
from eslam.slam.run.observers import FrameDone, RunEnd, RunObserverBase, RunStart
from eslam.slam.run.progress import finite_ate_pairs
from eslam.slam.run.resources import PeakMemory
from eslam.slam.run.stream_report import stream_metrics
from eslam.slam.state import (
    TRACKING_COLUMNS,
    SLAMState,
    degenerate_row,
    longest_failed_run,
    recovery_of,
    save_state,
)
from eslam.slam.tracking.base import RECOVERIES
from eslam.slam.tracking.feature_start import start_metrics
from eslam.slam.tracking.keyframe_offset import offset_metrics


@dataclass(frozen=True)
class WallTime:
    """Wall-clock time of this process's frames.

    Attributes:
        frames: frames this process processed (since the resume, for a resumed run).
        wall_s: seconds from the run's start to its last frame (the final mapping call
            included; the mesh and the final checkpoint not).
        first_frame_s: seconds of the first of those frames (with the map's first
            mapping call for a new run), None before it was done.
        poses_s: seconds from the first frame's pose to the last frame's (0 before two).
    """

    frames: int
    wall_s: float
    first_frame_s: float | None
    poses_s: float = 0.0


def speed_metrics(wall: WallTime, tracking_time: list[float]) -> dict:
    """metrics.json's speed keys (docs/evaluation.md, "metrics.json").

    - ``fps_wall`` = frames / wall_s: what a user waits for, everything included;
    - ``fps_wall_after_first`` = (frames - 1) / (wall_s - first_frame_s): the same without
      the first frame (the first mapping call and warm-up), the steady rate;
    - ``fps_poses_after_first`` = (frames - 1) / poses_s: the rate poses came at after
      the first, the final mapping call left out (what a live user sees while the camera
      runs; equal to the above but for that call when mapping is in turn);
    - ``fps_tracking`` = frames / total tracking time, over all the run's frames:
      Co-SLAM's definition (mapping and everything else left out), for comparison only.
    """
    metrics: dict = {"wall_frames": wall.frames, "wall_s": wall.wall_s}
    if wall.frames > 0 and wall.wall_s > 0:
        metrics["fps_wall"] = wall.frames / wall.wall_s
    if wall.first_frame_s is not None:
        metrics["first_frame_s"] = wall.first_frame_s
        steady = wall.wall_s - wall.first_frame_s
        if wall.frames > 1 and steady > 0:
            metrics["fps_wall_after_first"] = (wall.frames - 1) / steady
        if wall.frames > 1 and wall.poses_s > 0:
            metrics["fps_poses_after_first"] = (wall.frames - 1) / wall.poses_s
    tracking = float(np.sum(tracking_time))
    if tracking > 0:
        metrics["fps_tracking"] = len(tracking_time) / tracking
    return metrics


def quality_columns(state: SLAMState) -> dict[str, np.ndarray]:
    """The state's per-frame tracking quality by column name (:data:`TRACKING_COLUMNS`)."""
    rows = np.asarray(state.tracking_quality, dtype=np.float64).reshape(-1, len(TRACKING_COLUMNS))
    return dict(zip(TRACKING_COLUMNS, rows.T, strict=True))


def recovery_metrics(rows: list[list[float]]) -> dict:
    """metrics.json's recovery figures from the quality rows: frames recovered after a
    failed first try, by how (:data:`~eslam.slam.tracking.base.RECOVERIES`), and every
    relocalisation with the frame index of the keyframe it came from."""
    recoveries = [(frame, found) for frame, row in enumerate(rows) if (found := recovery_of(row))]
    return {
        "tracking_recovered_frames": {
            how: sum(1 for _, (kind, _) in recoveries if kind == how) for how in RECOVERIES
        },
        "tracking_relocalisations": [
            {"frame": frame, "keyframe": source}
            for frame, (kind, source) in recoveries
            if kind == "relocalised"
        ],
    }


def run_metrics(state: SLAMState, device: str, peak_memory_mb: float) -> dict:
    """metrics.json of a run: frames, device, FPT, peak memory, with a self-judging tracker
    the failed frames, the longest run of them, whether the last judged frame was tracked
    and the mean iterations (and with its degeneracy test on, the frames, not failed,
    with a degenerate direction), and with ground truth the ATE.

    FPT (seconds per frame) = (sum of tracking and mapping times) / frames. The ATE
    (rigid alignment, cm) uses the frames whose estimate and ground truth are both finite;
    the RPE (mm and degrees per frame) the consecutive pairs of such frames.
    """
    done = state.next_frame
    metrics: dict = {
        "frames": done,
        "device": device,
        "fpt_s": float(np.sum(state.tracking_time) + np.sum(state.mapping_time)) / max(done, 1),
        "peak_memory_mb": peak_memory_mb,
    }
    quality = quality_columns(state)
    failed = quality["tracking_failed"]
    judged = np.isfinite(failed)
    if judged.any():
        metrics["tracking_failures"] = int(failed[judged].sum())
        metrics["tracking_failed_longest_run"] = longest_failed_run(state.tracking_quality)
        metrics["tracking_ended_tracked"] = not bool(failed[judged][-1])
        metrics["tracking_iterations_mean"] = float(quality["tracking_iterations"][judged].mean())
        metrics.update(recovery_metrics(state.tracking_quality))
    metrics.update(loop_metrics(state))
    metrics.update(start_metrics(state))
    metrics.update(offset_metrics(state))
    if np.isfinite(quality["tracking_degenerate_directions"]).any():  # the test ran
        metrics["tracking_degenerate_frames"] = sum(map(degenerate_row, state.tracking_quality))
    gt = state.trajectory.gt_poses()
    if gt is not None:
        poses = state.trajectory.poses.detach().cpu().double().numpy()
        usable = finite_ate_pairs(poses, gt)
        if usable.sum() >= 3:
            metrics.update(absolute_trajectory_error(poses[usable], gt[usable]).as_cm())
            metrics["ate_frames"] = int(usable.sum())
        if (usable[:-1] & usable[1:]).any():
            metrics.update(relative_pose_error(poses, gt).as_dict())
    return metrics


def previous_metrics(run: RunDirectory) -> dict:
    """The run folder's metrics.json as it is ({} when missing or unreadable)."""
    try:
        metrics = json.loads(run.metrics.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return metrics if isinstance(metrics, dict) else {}


class RunWriter(RunObserverBase):
    """Writes the run folder ``run`` as the run goes (module doc).

    Args:
        run: the run folder.
        config: the run's configuration.
        memory: the peak-memory tracker.
        stream: the real-time reader of a real-time run (its counts go to metrics.json,
            the stream position of each processed frame to timings.json).
        clock: seconds (tests pass their own).

    Attributes:
        metrics: metrics.json's contents once the run finished (None before).
        saved_frames: frames in the last map.pt written (what a resume continues from;
            a resumed run's to begin with).
        resumed_at: frames the run had when this process resumed it (None: a new run).
    """

    def __init__(
        self,
        run: RunDirectory,
        config: ESLAMConfig,
        memory: PeakMemory,
        stream: LatestFrameReader | None = None,
        clock=time.perf_counter,
    ) -> None:
        self.run = run
        self.config = config
        self.memory = memory
        self.stream = stream
        self.clock = clock
        self.state: SLAMState | None = None
        self.metrics: dict | None = None
        self.saved_frames = 0
        self.resumed_at: int | None = None
        self._began = 0.0
        self._first_done: float | None = None
        self._last_done = 0.0
        self._last_pose = 0.0  # when the last frame's pose was done
        self.lags_s: list[float] = []  # real time: per frame, its age when its pose was done

    def on_start(self, start: RunStart) -> None:
        self.state = start.state
        self.saved_frames = start.state.next_frame
        self.resumed_at = start.state.next_frame if start.resumed else None
        self._began = self._last_done = self.clock()

    def _wall_time(self, frames: int) -> WallTime:
        """This process's wall time up to now, over its ``frames`` frames."""
        first = None if self._first_done is None else self._first_done - self._began
        poses = 0.0 if self._first_done is None else self._last_pose - self._first_done
        return WallTime(frames, self._last_done - self._began, first, poses)

    def on_frame(self, frame: FrameDone) -> None:
        self._last_done = self._last_pose = self.clock()
        if self.stream is not None:  # a real-time run starts at frame 0: index = delivered
            self.lags_s.append(self.stream.age_s(frame.index))
        if self._first_done is None:
            self._first_done = self._last_done
        # before the first frame with depth nothing is learnt: a resume must start at 0
        if len(self._state().keyframes) == 0:
            return
        if (frame.index + 1) % self.config.output.checkpoint_every == 0:
            with self._stop_on_failed_checkpoint():
                self.checkpoint()

    def on_finish(self, end: RunEnd) -> None:
        self._last_done = self.clock()  # after the final mapping call
        state = self._state()
        with self._stop_on_failed_checkpoint():
            self.checkpoint()
        if end.complete and self.config.output.mesh and state.field is not None:
            from eslam.io.mesh_files import write_mesh_ply
            from eslam.mesh.extract import extract_mesh

            mesh = extract_mesh(
                state.field, self.config.output.mesh_resolution, state.observed_views()
            )
            write_mesh_ply(self.run.mesh, mesh)
        self.metrics = self._write_metrics(state)

    def on_failure(self, error: BaseException, frames: int) -> None:
        if self.state is not None and frames > 0 and len(self.state.keyframes) > 0:
            with self._stop_on_failed_checkpoint():
                self.checkpoint()
            self._write_metrics(self._state())

    def _write_metrics(self, state: SLAMState) -> dict:
        """Write metrics.json (merged with the earlier one when no frame was added since
        the resume: module doc); return what was written."""
        metrics = run_metrics(state, str(self.memory.device), self.memory.peak_mb())
        frames = state.next_frame - (self.resumed_at or 0)
        speed = speed_metrics(self._wall_time(frames), state.tracking_time)
        if frames == 0:  # a finished run resumed again: its wall-clock keys stay
            speed = {k: v for k, v in speed.items() if k == "fps_tracking"}
        metrics.update(speed)
        metrics.update(concurrency_metrics(state, speed.get("wall_s", 0.0)))
        if self.stream is not None:
            metrics.update(stream_metrics(self.stream.counts(), frames, self.lags_s))
        if self.resumed_at is not None:
            previous = previous_metrics(self.run)
            if state.next_frame == self.resumed_at:
                metrics = {**previous, **metrics}
            peak = previous.get("peak_memory_mb")
            if isinstance(peak, int | float):  # the run's peak over all its processes
                metrics["peak_memory_mb"] = max(float(peak), metrics["peak_memory_mb"])
        write_json(self.run.metrics, metrics)
        return metrics

    @contextlib.contextmanager
    def _stop_on_failed_checkpoint(self) -> Iterator[None]:
        """A checkpoint that could not be written: the run stops, resumable from the last
        one that was (its frames named), or with the write's own error if none was."""
        try:
            yield
        except OutputError as error:
            if self.saved_frames == 0:
                raise
            resumable = self.stream is None  # a real-time run cannot be resumed
            raise RunStopped(error, self.saved_frames, self.run.root, resumable) from error

    def _state(self) -> SLAMState:
        if self.state is None:
            raise RuntimeError("the run writer was not started")
        return self.state

    def checkpoint(self) -> None:
        """map.pt, the trajectory so far and timings.json (atomically, in that order)."""
        state = self._state()
        save_state(self.run.map, state)
        self.saved_frames = state.next_frame
        trajectory = state.trajectory
        timestamps = trajectory.timestamps()
        poses = trajectory.poses.detach().cpu().double().numpy()
        write_tum_trajectory(self.run.trajectory, timestamps, poses)
        gt = trajectory.gt_poses()
        if gt is not None:
            usable = finite_ate_pairs(poses, gt)
            write_tum_trajectory(self.run.trajectory_gt, timestamps[usable], gt[usable])
        timings: dict = {
            "tracking_s": list(state.tracking_time),
            "mapping_s": list(state.mapping_time),
        }
        quality = quality_columns(state)
        if np.isfinite(quality["tracking_failed"]).any():  # per frame, null where not judged
            for key, column in quality.items():
                timings[key] = [None if np.isnan(v) else float(v) for v in column]
        if self.stream is not None:  # no resume: the run's frames are this process's
            timings["source_index"] = self.stream.source_indices[: state.next_frame]
            timings["lag_s"] = self.lags_s[: state.next_frame]
        write_json(self.run.timings, timings)
        if LOOPS in state.components:  # loop closure is on
            write_json(self.run.loops, state.components[LOOPS]["entries"])
