"""The run loop: frames in, observers out (ARCHITECTURE.md).

Single process, sequential, seeded. :func:`run_slam` opens the input (a recorded
sequence from ``config.data``, or any :class:`~eslam.data.source.FrameSource`), then
:class:`RunLoop` takes the frames one at a time: the tracker
(:mod:`eslam.slam.trackers`, chosen by ``tracking.method``) estimates each frame's pose
from the motion model's guess, the keyframe schedule says which frames are mapped,
and mapping refines the map and the window's poses. When the stream ends, its last
frame is mapped too. Everything the world sees goes through observers: the run writer
(checkpoints, trajectory, metrics, mesh), the log, the progress bar, and any passed in.

Nothing here needs the length of the input, and nothing changes process-wide state
(thread count, logger levels, the global random generator): the CLI owns those.

A frame that fails half way (unreadable file, out of memory, Ctrl-C) is rolled back,
the completed frames are checkpointed, and the error says how to resume.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from eslam.config import ESLAMConfig
from eslam.config.device import resolve_device
from eslam.data import RGBDSequence, open_sequence
from eslam.data.bags import with_detected_format
from eslam.data.depth_units import DepthCheck, sequence_depth_file, sequence_depth_scale
from eslam.data.feed import is_live, open_feed, runs_in_real_time
from eslam.data.prefetch import close_iterator
from eslam.data.realtime import replay_pace_error, timestamps_are_frame_numbers
from eslam.data.selection import sequence_timestamps
from eslam.data.source import FrameSource, SequenceSource, source_length
from eslam.errors import ConfigError, ESLAMError, InputError, RunInterrupted
from eslam.field.scene_field import SceneField
from eslam.field.triton_sampling import check_device
from eslam.render.rays import camera_directions
from eslam.slam.bounds_policy import (
    bound_from_frame,
    check_depth_found,
    check_some_depth,
    cover_keyframe,
    first_pose,
)
from eslam.slam.graphed import WindowMapper
from eslam.slam.keyframe_views import KeyframeViews
from eslam.slam.keyframes import KeyframeSchedule
from eslam.slam.mapping import MappingSettings, mapping_schedule
from eslam.slam.observed_view import observed_pixels
from eslam.slam.observers import (
    FrameDone,
    LogObserver,
    MappingDone,
    MappingStep,
    Observers,
    RunEnd,
    RunObserver,
    RunStart,
)
from eslam.slam.progress import ProgressObserver, finite_ate_pairs
from eslam.slam.resources import PeakMemory, device_clock
from eslam.slam.run_folder import (
    absolute_data_path,
    check_saved_frames,
    log_lock_takeover,
    open_run_folder,
)
from eslam.slam.run_writer import RunWriter
from eslam.slam.state import (
    FrameMark,
    SLAMState,
    degenerate_row,
    degenerate_stretch,
    initial_state,
    load_state,
    new_field,
    quality_row,
)
from eslam.slam.stops import interrupted_early, save_on_failure, stopped_error
from eslam.slam.stream_report import StreamLog
from eslam.slam.trackers import make_tracker, predict_pose
from eslam.slam.tracking import TrackingQuality
from eslam.slam.views import View, make_view, restrict_view, upload_frame
from eslam.types import Frame

log = logging.getLogger("eslam")

__all__ = ["RunLoop", "RunResult", "finite_ate_pairs", "preflight", "run_slam"]


@dataclass(frozen=True)
class RunResult:
    """What a finished run produced.

    Attributes:
        run_dir: the run folder.
        poses: (N, 4, 4) estimated camera-to-world poses.
        metrics: the contents of metrics.json.
    """

    run_dir: Path
    poses: np.ndarray
    metrics: dict


class RunLoop:
    """Processes frames one at a time against a run's state (module doc).

    Args:
        config: the run's configuration.
        state: the state to advance (fresh or resumed).
        device: the compute device.
        observers: told about every frame and mapping call.
        source: the input's name, for messages.
        logger: the run's log (warnings about frames, bound estimates and growth).
        end_on_interrupt: Ctrl-C (or SIGTERM) ends the stream as its end would: the frame
            in progress is rolled back, the last frame mapped, the run finished (a live
            or real-time run has no other way to end).
    """

    def __init__(
        self,
        config: ESLAMConfig,
        state: SLAMState,
        device: torch.device,
        observers: RunObserver,
        source: str,
        logger: logging.Logger = log,
        end_on_interrupt: bool = False,
    ) -> None:
        self.config = config
        self.state = state
        self.device = device
        self.observers = observers
        self.source = source
        self.log = logger
        self.tracker = make_tracker(config)
        self.schedule = KeyframeSchedule(config.mapping.every)
        self.mapping = MappingSettings(config.mapping, config.render, config.loss)
        self.mapper = WindowMapper(self.mapping, config.compute.cuda_graphs)
        self.directions = camera_directions(state.keyframes.intrinsics, device)
        self.views = KeyframeViews(
            state.keyframes, self.directions, device, config.mapping.view_cache_mb
        )
        self.end_on_interrupt = end_on_interrupt
        self.last_frame: Frame | None = None
        self._frames_without_depth = 0
        self._total: int | None = None
        self._last_failed = False
        self._before_mapping: tuple[dict[str, torch.Tensor], torch.Tensor] | None = None
        # no scene bound: one set too small is grown (or, growth off, warned about), a
        # matter of the bound and not of depth units
        self.depth_check = DepthCheck.for_run(
            config.data.depth_scale, bound=None, enabled=config.data.depth_check
        )

    def run(self, frames: Iterable[Frame], total: int | None, stop_after: int | None) -> RunEnd:
        """Process ``frames`` (``total`` of them in the whole run, None if unknown) until
        they end or ``stop_after`` frames are done; map the last frame at the end.

        On any error the frame in progress is rolled back before the error propagates;
        Ctrl-C with ``end_on_interrupt`` ends the stream instead (class doc).
        """
        state = self.state
        self._total = total
        began = time.perf_counter()
        iterator: Iterator[Frame] = iter(frames)
        complete = True
        interrupted = False
        while True:
            if stop_after is not None and state.next_frame >= stop_after:
                complete = total is not None and state.next_frame >= total
                break
            mark = state.mark()
            self._before_mapping = None
            try:
                frame = next(iterator, None)
                if frame is None:
                    break
                done = self.process(frame)
            except BaseException as error:
                self._rollback(mark)
                if not (self.end_on_interrupt and isinstance(error, KeyboardInterrupt)):
                    raise
                interrupted = True
                break
            try:
                self.observers.on_frame(done)  # the frame is complete: never rolled back
            except KeyboardInterrupt:
                if not self.end_on_interrupt:
                    raise
                interrupted = True
                break
        close_iterator(iterator)  # a reader thread stops taking frames it cannot process
        if complete:
            mark = state.mark()
            self._before_mapping = None
            try:
                self.map_last_frame()
            except BaseException:
                self._rollback(mark)
                raise
        return RunEnd(
            complete=complete,
            frames=state.next_frame,
            wall_s=time.perf_counter() - began,
            interrupted=interrupted,
        )

    def _rollback(self, mark: FrameMark) -> None:
        """Undo the frame begun at ``mark``, including a mapping call's changes to the
        field and to earlier keyframes' poses."""
        field_before = None
        if self._before_mapping is not None:
            field_state, poses = self._before_mapping
            field_before = SceneField.from_state(self.config.field, field_state).to(self.device)
            self.state.trajectory.set_poses(list(range(len(poses))), poses)
        self.state.rollback(mark, field_before)
        self.views.forget_from(mark.keyframes)

    def process(self, frame: Frame) -> FrameDone:
        """Track ``frame``, map it if it is a keyframe; return what happened."""
        state = self.state
        index = state.next_frame
        started = device_clock(self.device)
        has_depth = bool(frame.valid_depth.any())
        if not has_depth:
            self.log.warning(
                "frame %d (timestamp %.6f) has no valid depth: skipped (pose predicted, "
                "not tracked or mapped)",
                index,
                frame.timestamp,
            )
            check_some_depth(index, self._total, len(state.keyframes), self.source)
        tracked = False
        quality = None
        if index == 0:
            pose = first_pose(frame, self.log).to(self.device)
        else:
            # a failed frame's pose is a guess, not evidence of motion: hold still after it
            velocity = self.config.tracking.constant_velocity and not self._last_failed
            pose = predict_pose(state.trajectory.poses, velocity)
            if has_depth and state.field is not None and len(state.keyframes) > 0:
                rgb, depth = upload_frame(frame.rgb, frame.depth, self.device)
                view = make_view(rgb, depth, self.directions, self.config.tracking.border)
                if self.config.tracking.observed_only:
                    view = self._observed_part(view, pose, index)
                if view.sampleable_pixels() > 0:
                    result = self.tracker.track(state.field, view, pose, state.generator)
                    tracked, quality = True, result.quality
                    if not bool(torch.isfinite(result.pose).all()):
                        quality = non_finite_quality(quality)
                    if not quality_failed(quality):
                        pose = result.pose
        failed = quality_failed(quality)
        self._last_failed = failed
        if failed:
            self.log.warning(
                "frame %d (timestamp %.6f): tracking failed (%.0f%% inliers, residual %.1f mm):"
                " the motion model's pose is kept and the frame is no keyframe",
                index,
                frame.timestamp,
                100.0 * quality.inlier_fraction,
                1000.0 * quality.residual_m,
            )
        self._report_degeneracy(index, quality)
        if state.field is None:
            self._create_field(frame, has_depth, pose)
        state.trajectory.append(pose, frame.timestamp, frame.pose_gt)
        state.tracking_quality.append(quality_row(quality))
        done_tracking = device_clock(self.device)
        mapped = not failed and self.schedule.is_keyframe(index, has_depth, len(state.keyframes))
        if mapped:
            self.map_frame(frame, index)
        state.last_mapped = mapped or failed or not has_depth
        done = device_clock(self.device)
        state.tracking_time.append(done_tracking - started)
        state.mapping_time.append(done - done_tracking)
        self.last_frame = frame
        return FrameDone(
            index=index,
            pose=state.trajectory.poses[index],
            tracked=tracked,
            quality=quality,
            mapped=mapped,
            tracking_s=done_tracking - started,
            mapping_s=done - done_tracking,
            frame=frame,
        )

    def _observed_part(self, view: View, pose: torch.Tensor, index: int) -> View:
        """``view`` restricted to the pixels in observed space (``tracking.observed_only``);
        a frame with none left is logged (it keeps the motion model's pose)."""
        restricted = restrict_view(view, observed_pixels(view, pose, self.state.observed_views()))
        if restricted.sampleable_pixels() == 0 and view.sampleable_pixels() > 0:
            self.log.warning(
                "frame %d: none of its pixels lies in space a keyframe observed "
                "(tracking.observed_only): not tracked, the motion model's pose is kept",
                index,
            )
        return restricted

    def _report_degeneracy(self, index: int, quality: TrackingQuality | None) -> None:
        """Log where a stretch of degenerate views begins and ends (not every frame),
        read from the quality rows so far (so a resumed run continues its stretch)."""
        rows = self.state.tracking_quality
        degenerate = degenerate_row(quality_row(quality))
        after_degenerate = bool(rows) and degenerate_row(rows[-1])
        if degenerate and not after_degenerate:
            assert quality is not None
            self.log.warning(
                "frame %d: the view pins the pose down in only %d of 6 directions (smallest"
                " normalised information %.4f): along the rest the pose follows the motion"
                " model and may drift unseen (tracking_degenerate_frames in metrics.json)",
                index,
                6 - int(quality.degenerate_directions or 0),
                quality.information,
            )
        elif not degenerate and after_degenerate:
            self.log.info(
                "frame %d: the view constrains the whole pose again (frames %d-%d were degenerate)",
                index,
                index - degenerate_stretch(rows),
                index - 1,
            )

    def _create_field(self, frame: Frame, has_depth: bool, pose: torch.Tensor) -> None:
        """Build the field from the first frame with depth, seen from frame 0's pose."""
        if not has_depth:
            self._frames_without_depth += 1
            check_depth_found(self._frames_without_depth, self.source)
            return
        first = self.state.trajectory.poses[0] if len(self.state.trajectory) else pose
        bound = bound_from_frame(self.config.scene, frame, first, self.log)
        self.state.field = new_field(self.config, bound, self.device)

    def map_frame(self, frame: Frame, index: int) -> None:
        """Make frame ``index`` a keyframe and run one mapping call on its window."""
        state = self.state
        field = state.field
        if field is None:
            raise RuntimeError("mapping before the field exists")
        # a wrong depth unit mid-stream (a live source, a mixed folder) must not be mapped
        self.depth_check.check(frame.depth, self.source, f"frame {index} (a keyframe)")
        self._before_mapping = (
            {k: v.detach().clone() for k, v in field.state_dict().items()},
            state.trajectory.poses.clone(),
        )
        store = state.keyframes
        current = store.add(frame, index)
        pose = state.trajectory.poses[index]
        state.bound_warned = cover_keyframe(
            field,
            store.depth(current, self.device),
            store.intrinsics,
            pose,
            self.config.scene,
            state.generator,
            state.bound_warned,
            self.log,
        )
        window = state.window.select(store, current, state.generator)
        views = self.views.views(window)
        frame_of = store.frame_indices
        oldest = min(window, key=lambda k: frame_of[k])
        optimise = [self.config.mapping.optimise_poses and k != oldest for k in window]
        first = len(store) == 1
        schedule = mapping_schedule(self.config.mapping, first=first)

        def progress(done: int) -> None:
            self.observers.on_mapping_step(MappingStep(index, done, schedule.iterations, first))

        progress(0)
        result = self.mapper.map(
            field,
            views,
            store.poses[window].to(self.device),
            optimise,
            schedule,
            generator=state.generator,
            on_step=progress,
        )
        moved = [i for i, flag in enumerate(optimise) if flag]
        if moved:
            state.trajectory.set_poses([frame_of[window[i]] for i in moved], result.poses[moved])
        self.observers.on_mapping(
            MappingDone(
                index=index,
                window=tuple(frame_of[k] for k in window),
                iterations=schedule.iterations,
                loss=result.loss,
            )
        )

    def map_last_frame(self) -> None:
        """At the end of the stream: map its last frame unless that happened already."""
        state = self.state
        if state.last_mapped:
            return
        if self.last_frame is None:
            raise InputError(
                Path(self.source),
                "the last frame of the stream must be mapped, but it is no longer available",
                "start the run again",
            )
        started = device_clock(self.device)
        self.map_frame(self.last_frame, state.next_frame - 1)
        state.mapping_time[-1] += device_clock(self.device) - started
        state.last_mapped = True


def quality_failed(quality: TrackingQuality | None) -> bool:
    """Whether a tracker judged its frame failed (None: the tracker does not judge)."""
    return quality is not None and quality.failed


def non_finite_quality(quality: TrackingQuality | None) -> TrackingQuality:
    """The judgement of a frame whose tracker returned a non-finite pose: failed."""
    iterations = 0 if quality is None else quality.iterations
    return TrackingQuality(iterations, 0.0, float("inf"), failed=True)


def preflight(sequence: RGBDSequence, depth: DepthCheck | None = None) -> None:
    """Read the first and last frames of ``sequence``: the reader's checks raise on bad input.

    Opening a sequence already checked its layout, file pairs and poses; reading two
    frames checks the images (readable, sizes, depth units) before a run writes anything,
    and ``depth`` (when given) whether their depth is plausibly metres.
    Only recorded input has a last frame to read; a live source is checked as it goes.

    Raises:
        InputError: no frames, or a frame fails its reader's checks or ``depth``.
    """
    if len(sequence) == 0:
        raise InputError(sequence.root, "holds no frames", "check the --data path and its layout")
    for index in sorted({0, len(sequence) - 1}):
        frame = sequence[index]
        if depth is not None:
            where = sequence_depth_file(sequence, index) or sequence.root
            depth.check(frame.depth, where, f"frame {index}")


@contextlib.contextmanager
def run_log(path: Path) -> Iterator[logging.Logger]:
    """The run's logger while inside: INFO and above appended to ``path`` (log.txt).

    A private logger (not in logging's registry, so no global state changes) whose
    parent is the "eslam" logger: its records also reach the handlers a script attached
    there, and warnings reach stderr when there are none. Concurrent runs each have
    their own.
    """
    handler = logging.FileHandler(path, mode="a", encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    logger = logging.Logger("eslam.run", logging.INFO)
    logger.parent = log
    logger.addHandler(handler)
    try:
        yield logger
    except BaseException as error:
        log_stop(logger, error)
        raise
    finally:
        logger.removeHandler(handler)
        handler.close()


def log_stop(logger: logging.Logger, error: BaseException) -> None:
    """Log what stopped the run, as the user is told it (the ``eslam resume`` command
    included), so log.txt ends with it too; a bug (no user error, no interruption) with
    its traceback, which the screen shows but a closed terminal loses."""
    if isinstance(error, ESLAMError | KeyboardInterrupt):
        logger.error("stopped: %s", str(error) or type(error).__name__)
    else:
        logger.error("stopped by an error: %s", error, exc_info=error)


def _open_input(
    config: ESLAMConfig, source: FrameSource | None
) -> tuple[FrameSource | None, RGBDSequence | None]:
    if source is not None:
        return source, None
    if config.data.path is None:
        raise ConfigError("data.path is not set (pass --data PATH or set data.path in the config)")
    sequence = open_sequence(config.data)
    preflight(
        sequence,
        DepthCheck.for_run(
            sequence_depth_scale(sequence), bound=None, enabled=config.data.depth_check
        ),
    )
    if (
        config.data.realtime
        and config.data.replay_fps is None
        and timestamps_are_frame_numbers(sequence_timestamps(sequence))
    ):
        raise replay_pace_error(str(sequence.root))
    return None, sequence


def check_resumable(config: ESLAMConfig, source: FrameSource | None, run_dir: Path) -> None:
    """Refuse to resume a real-time run: which frames it processed depended on timing (the
    rest were dropped), so no frame "follows its checkpoint" (docs/live.md).

    Raises:
        ConfigError: the run in ``run_dir`` ran in real time, or ``source`` is live.
    """
    if config.data.realtime or is_live(source):
        raise ConfigError(
            f"{run_dir} ran in real time (frames were dropped as they arrived), so it cannot "
            "be resumed: start a new run (its trajectory, map and mesh stay where they are)"
        )


def run_slam(
    config: ESLAMConfig,
    run_dir: str | Path,
    resume: bool = False,
    stop_after: int | None = None,
    overwrite: bool = False,
    *,
    source: FrameSource | None = None,
    observers: Sequence[RunObserver] = (),
) -> RunResult:
    """Run ESLAM and write the run folder ``run_dir``.

    Recorded input (``config.data``, when ``source`` is None) is checked before
    anything is written (the sequence opens, its first and last frames read and pass
    the reader's checks), so bad input leaves an earlier run in ``run_dir`` untouched.
    The run holds the folder's lock while it writes, and stores ``data.path`` absolute
    and the input's fingerprint (:mod:`eslam.slam.run_folder`).

    Args:
        config: the fully resolved configuration (saved as config.yaml).
        run_dir: output folder (created); see :class:`~eslam.io.run_dir.RunDirectory`.
        resume: continue the run in ``run_dir``: from map.pt, or from frame 0 when it
            stopped before saving one. A recorded sequence must match the run's
            input.json and continues at the next frame; a given ``source`` must yield
            the frames that follow the checkpoint.
        stop_after: stop (checkpointed) after this many frames in total, as an
            interruption would; used by tests of ``resume``.
        overwrite: start a new run in a folder that already holds one (its files are
            replaced one by one as the new run writes them).
        source: frames to run on instead of ``config.data`` (a live stream, a generator:
            :class:`~eslam.data.source.IterableSource`); its length may be unknown.
        observers: more observers (a viewer, a stream of poses), called after the run
            writer, the log and the progress bar.

    Raises:
        ConfigError, InputError: bad configuration or input, before any file is written;
            also a live run holding ``run_dir`` or (resume) a sequence that changed.
        RunStopped: an error once the run folder was opened (the completed frames are
            saved; the message names ``eslam resume``).
        RunInterrupted: Ctrl-C (or the CLI's SIGTERM) once the run folder was opened.
    """
    device = resolve_device(config.device)
    check_device(config.field.plane_sampling, device)
    config = absolute_data_path(config)
    config = dataclasses.replace(config, data=with_detected_format(config.data))
    if resume:
        check_resumable(config, source, Path(run_dir))
    source, sequence = _open_input(config, source)
    intrinsics = source.intrinsics if source is not None else sequence.intrinsics  # type: ignore[union-attr]
    folder = open_run_folder(run_dir, config, sequence, resume, overwrite)
    writer: RunWriter | None = None
    try:
        with folder as (run, lock), run_log(run.log) as run_logger:
            log_lock_takeover(lock, run_logger)
            if resume and run.map.is_file():
                state = load_state(run.map, config, device)
                check_saved_frames(sequence, state.next_frame, run.map)
            else:
                if resume:
                    run_logger.info("no frame was saved before: the run starts at frame 0")
                state = initial_state(config, intrinsics, device)
            if sequence is not None:
                source = SequenceSource(sequence, start=state.next_frame)
            assert source is not None
            feed = open_feed(source, config.data, source.name)
            real_time = runs_in_real_time(source, config.data)
            memory = PeakMemory(device)
            writer = RunWriter(run, config, memory, feed.stream)
            writer.saved_frames = state.next_frame
            progress = ProgressObserver(config.output.progress, stream=feed.stream)
            reports = [] if feed.stream is None else [StreamLog(feed.stream, run_logger)]
            try:
                remaining = source_length(source)
                total = None if remaining is None else state.next_frame + remaining
                memory.start()
                everyone = Observers(
                    [writer, LogObserver(run_logger), progress, *reports, *observers]
                )
                loop = RunLoop(config, state, device, everyone, source.name, run_logger, real_time)
                if resume and not state.last_mapped and isinstance(source, SequenceSource):
                    loop.last_frame = source.frame(state.next_frame - 1)
                try:  # a failure while starting or finishing (the mesh) is a failure too
                    everyone.on_start(
                        RunStart(config, run.root, state, device, source.name, remaining, resume)
                    )
                    with feed:
                        end = loop.run(feed.frames, total, stop_after)
                    everyone.on_finish(end)
                except BaseException as error:
                    save_on_failure(everyone, error, state.next_frame, run_logger)
                    raise
            except BaseException as error:
                stopped = stopped_error(error, writer.saved_frames, run.root, not real_time)
                if stopped is error:
                    raise
                raise stopped from error
            finally:
                progress.close()  # before anyone prints the error: it gets its own line
            poses = state.trajectory.poses.detach().cpu().double().numpy()
            return RunResult(run_dir=run.root, poses=poses, metrics=dict(writer.metrics or {}))
    except KeyboardInterrupt as interrupt:
        if writer is not None or isinstance(interrupt, RunInterrupted):
            raise  # already said what was saved
        raise interrupted_early(interrupt, Path(run_dir), resume) from interrupt
