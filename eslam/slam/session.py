"""A run from the configuration to its folder: resolve, check the input, wire, run.

:func:`run_slam` is what the CLI, the sweep and the API call: it resolves the config
once (:func:`resolve_config`: device, absolute data path, detected format), opens and
checks the input before anything is written, opens the run folder (lock, fingerprint),
builds the state (fresh or resumed), the observers (the run writer, the log, the
progress bar, yours) and the components (the tracking front end and the mapping back
end, built from the config through their registries unless passed in), and hands the
frames to :class:`~eslam.slam.loop.RunLoop`.

A run that stops (an error, Ctrl-C, SIGTERM via the CLI) keeps its completed frames
and says how to resume (:mod:`eslam.slam.run.stops`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.config import ESLAMConfig
from eslam.config.device import resolve_device
from eslam.data import RGBDSequence, open_sequence
from eslam.data.bags import with_detected_format
from eslam.data.depth_units import DepthCheck, sequence_depth_file, sequence_depth_scale
from eslam.data.feed import is_live, open_feed, runs_in_real_time
from eslam.data.realtime import replay_pace_error, timestamps_are_frame_numbers
from eslam.data.selection import sequence_timestamps
from eslam.data.source import FrameSource, SequenceSource, source_length
from eslam.errors import ConfigError, ESLAMError, InputError, RunInterrupted
from eslam.field.plane_sampling import PLANE_SAMPLINGS
from eslam.slam.context import RunContext
from eslam.slam.loop import RunLoop
from eslam.slam.loops.pose_graph import import_gtsam
from eslam.slam.mapping.backend import BackEnd, make_back_end
from eslam.slam.mapping.workers import worker_kind
from eslam.slam.run.folder import (
    absolute_data_path,
    check_saved_frames,
    log_lock_takeover,
    open_run_folder,
)
from eslam.slam.run.frame_log import FrameLogObserver
from eslam.slam.run.observers import LogObserver, Observers, RunObserver, RunStart
from eslam.slam.run.progress import ProgressObserver
from eslam.slam.run.resources import PeakMemory
from eslam.slam.run.stops import interrupted_early, save_on_failure, stopped_error
from eslam.slam.run.stream_report import StreamLog
from eslam.slam.run.writer import RunWriter
from eslam.slam.state import initial_state, load_state
from eslam.slam.tracking.frontend import FrontEnd, TrackingFrontEnd

log = logging.getLogger("eslam")

__all__ = ["Components", "RunResult", "preflight", "resolve_config", "run_slam"]


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


@dataclass(frozen=True)
class Components:
    """Builders of a run's components, for callers that bring their own (tests,
    benchmarks, code outside eslam); each takes the run's :class:`RunContext`. None:
    the config's (:class:`~eslam.slam.tracking.frontend.TrackingFrontEnd`,
    :func:`~eslam.slam.mapping.backend.make_back_end`)."""

    front_end: Callable[[RunContext], FrontEnd] | None = None
    back_end: Callable[[RunContext], BackEnd] | None = None

    def build(self, context: RunContext) -> tuple[FrontEnd, BackEnd]:
        front = TrackingFrontEnd(context) if self.front_end is None else self.front_end(context)
        back = make_back_end(context) if self.back_end is None else self.back_end(context)
        return front, back


def resolve_config(config: ESLAMConfig) -> ESLAMConfig:
    """``config`` as a run saves it: ``data.path`` absolute, ``data.format`` detected (a
    bag's). The sweep resolves its cells' configs with it, so a finished cell's
    config.yaml compares equal to the cell's."""
    config = absolute_data_path(config)
    return dataclasses.replace(config, data=with_detected_format(config.data))


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


def concurrent_mapping(
    config: ESLAMConfig, real_time: bool, resume: bool, logger: logging.Logger
) -> bool:
    """Whether the run maps beside the tracker: ``mapping.concurrent``, or when it is not
    set, whether the run is in real time (unless it closes loops, which needs mapping in
    turn); a resumed run maps in turn. Either exception is said in log.txt."""
    wanted = config.mapping.concurrent
    if wanted is None and real_time and config.mapping.loops.enabled:
        logger.info("loop closure is on: this real-time run maps in turn (mapping.concurrent)")
        return False
    concurrent = real_time if wanted is None else wanted
    if concurrent and resume:
        logger.info("a resumed run maps in turn (mapping.concurrent applies to new runs)")
        return False
    return concurrent


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
    components: Components = Components(),
) -> RunResult:
    """Run ESLAM and write the run folder ``run_dir``.

    Recorded input (``config.data``, when ``source`` is None) is checked before
    anything is written (the sequence opens, its first and last frames read and pass
    the reader's checks), so bad input leaves an earlier run in ``run_dir`` untouched.
    The run holds the folder's lock while it writes, and stores ``data.path`` absolute
    and the input's fingerprint (:mod:`eslam.slam.run.folder`).

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
        components: builders of the tracking front end and the mapping back end, for
            your own (default: the config's).

    Raises:
        ConfigError, InputError: bad configuration or input, before any file is written;
            also a live run holding ``run_dir`` or (resume) a sequence that changed.
        RunStopped: an error once the run folder was opened (the completed frames are
            saved; the message names ``eslam resume``).
        RunInterrupted: Ctrl-C (or the CLI's SIGTERM) once the run folder was opened.
    """
    config = resolve_config(config)
    device = resolve_device(config.device)
    PLANE_SAMPLINGS.check(config.field.plane_sampling, device)
    worker_kind(config.mapping.concurrent_worker, device)  # the process only on a CPU
    if config.mapping.loops.enabled:
        import_gtsam()  # a missing extra is named before the run folder is touched
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
                logs = [LogObserver(run_logger), FrameLogObserver(run_logger)]
                everyone = Observers([writer, *logs, progress, *reports, *observers])
                camera = state.keyframes.intrinsics  # the camera the keyframes are stored with
                concurrent = concurrent_mapping(config, real_time, resume, run_logger)
                context = RunContext.build(
                    config, device, camera, everyone, run_logger, source.name, concurrent, real_time
                )
                front_end, back_end = components.build(context)
                loop = RunLoop(state, front_end, back_end, everyone, real_time)
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
