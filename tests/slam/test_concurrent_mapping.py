"""Mapping beside the tracker (mapping.concurrent): tracks, hands over whole maps only,
stops and resumes, accounts for every frame of a real-time replay."""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.config import load_config
from eslam.data import open_sequence
from eslam.data.source import IterableSource
from eslam.errors import ConfigError
from eslam.field.scene_field import SceneField
from eslam.slam.mapping.concurrent_mapping import (
    ConcurrentBackEnd,
    copy_field,
    same_layout,
    split_warm_start,
)
from eslam.slam.mapping.mapper import (
    LATER_WARM_START_LR,
    MappingResult,
    MappingSchedule,
    mapping_schedule,
)
from eslam.slam.mapping.warm_start import WarmStart
from eslam.slam.mapping.workers import ProcessWorker
from eslam.slam.run.observers import FrameDone, RunObserverBase
from eslam.slam.session import Components, concurrent_mapping, run_slam
from eslam.slam.state import load_state
from eslam.slam.tracking.frontend import TrackedFrame
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY_FRAMES, static_ate_cm, tiny_config

QUICK = ("mapping.first_iterations=5", "mapping.iterations=3", "output.checkpoint_every=100")
CONCURRENT = ("mapping.concurrent=true", "output.checkpoint_every=100")


def keyframes_of(run: Path, config) -> int:
    return len(load_state(run / "map.pt", config, torch.device("cpu")).keyframes)


@pytest.mark.slow
def test_a_concurrent_run_tracks_and_maps_every_keyframe_it_keeps(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    config = tiny_config(tiny_sequence, *CONCURRENT)
    result = run_slam(config, tmp_path / "run")
    metrics = result.metrics
    gt = open_sequence(config.data).gt_poses()
    assert metrics["frames"] == TINY_FRAMES
    assert metrics["ate_rmse_cm"] < static_ate_cm(gt) / 2  # a tracker that never moves fails
    assert metrics["mapping_concurrent"] is True
    # every keyframe the run kept was mapped by a whole call (the last frame's included)
    assert metrics["mapping_calls"] == keyframes_of(tmp_path / "run", config) >= 2
    assert metrics["mapping_queue_max"] >= 1 and metrics["mapping_calls_per_s"] > 0
    log = (tmp_path / "run" / "log.txt").read_text()
    assert f"mapped frame {TINY_FRAMES - 1}:" in log


class SlowMapper:
    """A mapper that writes version -v into the field's parameters one tensor at a time,
    sleeping in between: a tracker reading the field mid-call would see two versions (or
    a version and the map before it)."""

    def __init__(self) -> None:
        self.version = 0
        self.threads: set[int] = set()

    def map(self, field, views, poses, optimise, schedule, generator, on_step=None):
        self.threads.add(threading.get_ident())
        self.version += 1
        with torch.no_grad():
            for parameter in field.parameters():
                parameter.fill_(-float(self.version))
                time.sleep(0.005)
        return MappingResult(poses=poses.clone(), loss=torch.zeros(()))


class VersionReader:
    """A front end that reads the first value of each of the map's parameters, then
    gives the ground-truth pose (the map is no map: the mapper writes constants)."""

    def __init__(self) -> None:
        self.seen: list[set[float]] = []

    def track(self, frame, index, state) -> TrackedFrame:
        if state.field is not None and len(state.keyframes) > 0:
            self.seen.append({float(p.flatten()[0]) for p in state.field.parameters()})
        time.sleep(0.1)  # a tracker takes time: calls complete while frames go on
        pose = torch.as_tensor(frame.pose_gt, dtype=torch.float32)
        return TrackedFrame(pose=pose, has_depth=True, tracked=True)


@pytest.mark.slow
@pytest.mark.parametrize("worker", ["thread", "process"])
def test_the_tracker_reads_only_whole_maps_from_a_slow_mapper(
    tiny_sequence: Path, tmp_path: Path, worker: str
) -> None:
    mapper, reader = SlowMapper(), VersionReader()
    built: list[ConcurrentBackEnd] = []

    def back_end(context) -> ConcurrentBackEnd:
        built.append(ConcurrentBackEnd(context))
        built[0].mapper = mapper
        return built[0]

    config = tiny_config(
        tiny_sequence,
        *CONCURRENT,
        "mapping.first_warm_start=none",
        "output.mesh=false",
        f"mapping.concurrent_worker={worker}",
    )
    run_slam(config, tmp_path / "run", components=Components(lambda _: reader, back_end))
    assert built[0].worker is not None and built[0].worker.kind == worker
    if worker == "thread":  # beside the loop, in a thread of its own
        assert mapper.threads and threading.get_ident() not in mapper.threads
    else:  # the process mapped a copy of the mapper: this one never ran
        assert mapper.version == 0 and not mapper.threads
    assert len(reader.seen) == TINY_FRAMES - 1
    versions = []
    for seen in reader.seen:  # the map before the first call (random), or one version
        written = {value for value in seen if value <= -1 and value.is_integer()}
        if written:
            assert seen == written and len(written) == 1, reader.seen  # never torn
            versions.append(-written.pop())
    assert versions == sorted(versions) and len(set(versions)) >= 3, reader.seen


def started_processes(monkeypatch: pytest.MonkeyPatch) -> list:
    """The mapping processes the run starts (the list fills as they start)."""
    started: list = []
    start = ProcessWorker._start

    def recorded(worker: ProcessWorker) -> None:
        start(worker)
        started.append(worker.process)

    monkeypatch.setattr(ProcessWorker, "_start", recorded)
    return started


@pytest.mark.slow
def test_a_stopped_concurrent_run_holds_whole_calls_and_resumes_in_turn(
    tiny_sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tiny_config(tiny_sequence, *CONCURRENT)
    run = tmp_path / "run"
    processes = started_processes(monkeypatch)
    stopped = run_slam(config, run, stop_after=6)
    # the call in flight and the waiting keyframe were mapped before map.pt was written
    assert stopped.metrics["mapping_calls"] == keyframes_of(run, config)
    assert stopped.metrics["mapping_worker"] == "process"  # auto, on a CPU
    assert not any(t.name.startswith("eslam-mapping") for t in threading.enumerate())
    assert len(processes) == 1 and processes[0].poll() == 0  # one process, ended cleanly
    resumed = run_slam(load_config(run / "config.yaml"), run, resume=True)
    assert len(resumed.poses) == TINY_FRAMES
    assert "a resumed run maps in turn" in (run / "log.txt").read_text()
    gt = open_sequence(config.data).gt_poses()
    assert resumed.metrics["ate_rmse_cm"] < static_ate_cm(gt) / 2


@pytest.mark.slow
def test_a_real_time_replay_maps_beside_and_accounts_for_every_frame(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    # real time maps beside the tracker unless told otherwise; a replay faster than this
    # machine drops frames, and every frame received is processed or dropped
    config = tiny_config(
        tiny_sequence,
        *QUICK,
        "data.realtime=true",
        "data.replay_fps=200",
        "mapping.first_warm_start=tsdf",
        "mapping.first_warm_start_steps=20",
        "mapping.first_warm_start_points=500",
        "mapping.first_warm_start_lead=5",  # the rest of the warm start in the worker
    )
    result = run_slam(config, tmp_path / "rt")
    metrics = result.metrics
    assert metrics["mapping_concurrent"] is True
    assert metrics["frames_received"] == TINY_FRAMES
    assert metrics["frames"] + metrics["frames_dropped"] == TINY_FRAMES
    timings = json.loads((tmp_path / "rt" / "timings.json").read_text())
    assert len(timings["lag_s"]) == metrics["frames"] == len(timings["source_index"])
    assert 0 <= metrics["tracking_lag_s_mean"] <= metrics["tracking_lag_s_max"]
    assert timings["source_index"][-1] == TINY_FRAMES - 1  # the newest is processed
    # ... and mapped at the end, every keyframe kept by a whole call
    assert f"mapped frame {metrics['frames'] - 1}:" in (tmp_path / "rt" / "log.txt").read_text()
    assert metrics["mapping_calls"] == keyframes_of(tmp_path / "rt", config)


class CtrlCAt(RunObserverBase):
    """Presses Ctrl-C once frame ``index`` is done."""

    def __init__(self, index: int) -> None:
        self.index = index

    def on_frame(self, frame: FrameDone) -> None:
        if frame.index == self.index:
            raise KeyboardInterrupt


@pytest.mark.slow
def test_ctrl_c_in_a_concurrent_live_run_waits_for_the_call_and_saves(
    tiny_sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tiny_config(tiny_sequence, *QUICK)
    sequence = open_sequence(config.data)

    def camera():  # a live camera at ~100 fps, endless
        i = 0
        while True:
            yield sequence[i % len(sequence)]
            i += 1
            time.sleep(0.01)

    source = IterableSource(sequence.intrinsics, camera(), name="camera", live=True)
    processes = started_processes(monkeypatch)
    result = run_slam(config, tmp_path / "live", source=source, observers=[CtrlCAt(4)])
    assert len(processes) == 1 and processes[0].poll() == 0
    run = tmp_path / "live"
    for name in ("map.pt", "trajectory.txt", "mesh.ply", "metrics.json"):
        assert (run / name).is_file(), name
    metrics = result.metrics
    assert metrics["frames"] == 5 and metrics["mapping_concurrent"] is True
    assert metrics["mapping_calls"] == keyframes_of(run, config)
    assert not any(t.name.startswith("eslam-mapping") for t in threading.enumerate())


def test_a_finished_call_reaches_the_tracker_in_place_or_as_a_new_field() -> None:
    config = load_config(DEMO_CONFIG).field
    bound = torch.tensor([[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]])
    tracker = SceneField(config, bound, torch.Generator().manual_seed(0))
    mapped = SceneField(config, bound, torch.Generator().manual_seed(1))
    assert same_layout(mapped, tracker)
    assert copy_field(mapped, tracker) is tracker  # in place: whoever holds it sees it
    for key, value in mapped.state_dict().items():
        assert torch.equal(tracker.state_dict()[key], value), key
    mapped.grow(torch.tensor([[-1.0, 2.0], [-1.0, 1.0], [-1.0, 1.0]]))
    assert not same_layout(mapped, tracker)
    grown = copy_field(mapped, tracker)
    assert grown is not tracker and grown is not mapped  # the mapper keeps its own
    np.testing.assert_array_equal(grown.bound.numpy(), mapped.bound.numpy())


class RecordingMapper:
    """The run's mapper, recording each call's (warm-start steps, rendering steps)."""

    def __init__(self, mapper) -> None:
        self.mapper = mapper
        self.calls: list[tuple[int, int]] = []
        self.windows: list[int] = []  # each call's keyframes

    def map(self, field, views, poses, optimise, schedule, generator, on_step=None):
        warm = 0 if schedule.warm_start is None else schedule.warm_start.steps
        self.calls.append((warm, schedule.iterations))
        self.windows.append(len(views))
        return self.mapper.map(field, views, poses, optimise, schedule, generator)


class RecordingBackEnd:
    """Builds the run's concurrent back end with a :class:`RecordingMapper` (use a thread
    worker: the calls are recorded in this process)."""

    def __init__(self) -> None:
        self.built: ConcurrentBackEnd | None = None

    def __call__(self, context) -> ConcurrentBackEnd:
        self.built = ConcurrentBackEnd(context)
        self.built.mapper = RecordingMapper(self.built.mapper)
        return self.built

    def calls(self) -> list[tuple[int, int]]:
        assert self.built is not None
        return self.built.mapper.calls


@pytest.mark.slow
def test_a_warm_start_lead_gives_the_tracker_the_worker_s_steps_before_rendering(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    recording = RecordingBackEnd()
    config = tiny_config(
        tiny_sequence,
        *CONCURRENT,
        "mapping.concurrent_worker=thread",  # the recording mapper runs in this process
        "mapping.first_warm_start=tsdf",
        "mapping.first_warm_start_steps=40",
        "mapping.first_warm_start_points=500",
        "mapping.first_warm_start_lead=10",
        "mapping.realtime_iterations=1",  # a recording: not real time, so neither is taken
        "mapping.realtime_first_iterations=1",
        "output.mesh=false",
    )
    result = run_slam(config, tmp_path / "run", components=Components(back_end=recording))
    calls = recording.calls()
    first_iterations = config.mapping.first_iterations
    # the first keyframe: 10 steps before the first pose, then the worker's 30 on their
    # own (published to the tracker), then its rendering steps; one call counted
    assert calls[0] == (30, 0) and calls[1] == (0, first_iterations), calls
    assert all(call == (0, config.mapping.iterations) for call in calls[2:]), calls
    assert (
        result.metrics["mapping_calls"] == len(calls) - 1 == keyframes_of(tmp_path / "run", config)
    )


def real_time_config(sequence: Path, *extra: str):
    """The tiny run replayed in real time, its calls in a thread (a recording mapper runs
    in this process), 2 rendering steps for the first call and 1 for each later one."""
    return tiny_config(
        sequence,
        *QUICK,  # mapping.first_iterations=5, mapping.iterations=3
        "data.realtime=true",
        "data.replay_fps=200",
        "mapping.concurrent_worker=thread",
        "mapping.realtime_iterations=1",
        "mapping.realtime_first_iterations=2",
        "output.mesh=false",
        *extra,
    )


@pytest.mark.slow
def test_a_real_time_run_maps_with_its_own_step_count(tiny_sequence: Path, tmp_path: Path) -> None:
    recording = RecordingBackEnd()
    # the CPU preset's 60 TSDF steps a later call: the test below
    config = real_time_config(tiny_sequence, "mapping.realtime_warm_start=0")
    result = run_slam(config, tmp_path / "rt", components=Components(back_end=recording))
    calls = recording.calls()
    assert calls[0] == (0, 2), calls
    assert len(calls) >= 2 and all(call == (0, 1) for call in calls[1:]), calls
    assert result.metrics["mapping_calls"] == len(calls)


@pytest.mark.slow
def test_a_real_time_call_s_warm_start_reaches_the_tracker_before_its_rendering_steps(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    recording = RecordingBackEnd()
    published: list[int] = []
    config = real_time_config(
        tiny_sequence, "mapping.realtime_warm_start=4", "mapping.first_warm_start_points=200"
    )

    def build(context) -> ConcurrentBackEnd:
        back_end = recording(context)
        publish = back_end._publish
        back_end._publish = lambda state: (published.append(1), publish(state))[1]
        return back_end

    result = run_slam(config, tmp_path / "rt", components=Components(back_end=build))
    calls, windows = recording.calls(), recording.built.mapper.windows
    # the first call as before; every later one in two parts: its 4 TSDF steps over the
    # window, published to the tracker, then its rendering step
    assert calls[0] == (0, 2) and len(calls) >= 3 and len(calls) % 2 == 1, calls
    assert calls[1::2] == [(4, 0)] * (len(calls) // 2), calls
    assert calls[2::2] == [(0, 1)] * (len(calls) // 2), calls
    assert windows[1] == windows[2] >= 2 and windows[1::2] == windows[2::2], windows
    assert len(published) == len(calls)  # each part reached the tracker's map
    assert result.metrics["mapping_calls"] == 1 + len(calls) // 2


def test_the_real_time_step_counts_are_taken_in_real_time_only() -> None:
    settings = ["mapping.iterations=15", "mapping.first_iterations=30"]
    config = load_config(
        DEMO_CONFIG,
        [*settings, "mapping.realtime_iterations=8", "mapping.realtime_first_iterations=10"],
    )
    assert mapping_schedule(config.mapping, first=False, real_time=True).iterations == 8
    assert mapping_schedule(config.mapping, first=False, real_time=False).iterations == 15
    assert mapping_schedule(config.mapping, first=True, real_time=True).iterations == 10
    assert mapping_schedule(config.mapping, first=True, real_time=False).iterations == 30
    unset = load_config(
        DEMO_CONFIG,
        [*settings, "mapping.realtime_iterations=null", "mapping.realtime_first_iterations=null"],
    ).mapping
    assert mapping_schedule(unset, first=False, real_time=True).iterations == 15
    assert mapping_schedule(unset, first=True, real_time=True).iterations == 30
    for name in ("realtime_iterations", "realtime_first_iterations", "realtime_warm_start"):
        with pytest.raises(ConfigError, match=name):
            load_config(DEMO_CONFIG, [f"mapping.{name}=-1"])


def test_a_real_time_warm_start_begins_later_calls_in_real_time_only() -> None:
    config = load_config(
        DEMO_CONFIG,
        ["mapping.realtime_warm_start=30", "mapping.first_warm_start_points=2000"],
    ).mapping
    later = mapping_schedule(config, first=False, real_time=True)
    assert later.warm_start == WarmStart(30, 2000, lr_factor=LATER_WARM_START_LR)
    assert later.iterations == config.realtime_iterations
    assert mapping_schedule(config, first=False, real_time=False).warm_start is None
    first = mapping_schedule(config, first=True, real_time=True)  # the first: its own
    assert first.warm_start == WarmStart(config.first_warm_start_steps, 2000)
    none = load_config(DEMO_CONFIG, ["mapping.realtime_warm_start=0"]).mapping
    assert mapping_schedule(none, first=False, real_time=True).warm_start is None


def test_a_warm_start_lead_splits_the_steps_between_the_first_pose_and_the_worker() -> None:
    first = MappingSchedule(30, 2.0, 2000, warm_start=WarmStart(400, 4000))
    lead, rest = split_warm_start(first, 100)
    assert lead.warm_start == WarmStart(100, 4000)  # before the tracker gets the map
    assert rest.warm_start == WarmStart(300, 4000)  # in the worker, before ...
    assert rest.iterations == 30 and rest.lr_factor == 2.0  # ... the rendering steps
    lead, rest = split_warm_start(first, None)  # all before the first pose (the default)
    assert lead.warm_start == WarmStart(400, 4000) and rest.warm_start is None
    assert split_warm_start(first, 1000)[1].warm_start is None
    with pytest.raises(ValueError, match="warm start"):
        split_warm_start(MappingSchedule(30, 2.0, 2000), 10)
    with pytest.raises(ConfigError, match="first_warm_start_lead"):
        load_config(DEMO_CONFIG, ["mapping.first_warm_start_lead=-1"])


def test_concurrent_mapping_with_loop_closure_is_refused_or_not_chosen() -> None:
    with pytest.raises(ConfigError, match=r"mapping\.concurrent=false"):
        load_config(DEMO_CONFIG, ["mapping.concurrent=true", "mapping.loops.enabled=true"])
    log = logging.getLogger("test-concurrent")
    looping = load_config(DEMO_CONFIG, ["mapping.loops.enabled=true"])
    assert not concurrent_mapping(looping, real_time=True, resume=False, logger=log)
    plain = load_config(DEMO_CONFIG)
    assert concurrent_mapping(plain, real_time=True, resume=False, logger=log)
    assert not concurrent_mapping(plain, real_time=True, resume=True, logger=log)
    assert not concurrent_mapping(plain, real_time=False, resume=False, logger=log)
