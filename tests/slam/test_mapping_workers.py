"""Where a concurrent run maps (mapping.concurrent_worker): a thread or a process of its
own give the same call bit for bit, the process maps the run's field in place, sends
back errors, survives Ctrl-C, is reported when it dies and is gone once closed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from eslam.config import load_config
from eslam.errors import ConfigError
from eslam.render.rays import camera_directions
from eslam.slam.cuda_graphs import WindowMapper
from eslam.slam.mapping.mapper import MappingResult, MappingSchedule, MappingSettings
from eslam.slam.mapping.workers import (
    MappingCall,
    MappingProcessError,
    ProcessWorker,
    ThreadWorker,
    worker_kind,
)
from eslam.slam.state import new_field
from eslam.slam.views import make_view
from eslam.synthetic import SynthConfig, build_scene, generate_sequence, scene_bound
from eslam.workflows.demo import DEMO_CONFIG

SCENE = SynthConfig(frames=3, width=40, height=30, seed=1)
CPU = torch.device("cpu")
PLANES = "geometry.levels.fine.planes"
ROOT = Path(__file__).resolve().parents[2]


def mapping_call() -> tuple[MappingCall, MappingSettings]:
    """A window of the scene's 3 frames (the first pose held) on a fresh field."""
    config = load_config(
        DEMO_CONFIG, ["mapping.rays=120", "render.samples_stratified=4", "render.samples_surface=2"]
    )
    frames = list(generate_sequence(SCENE))
    directions = camera_directions(frames[0].intrinsics)
    views = [
        make_view(torch.from_numpy(f.rgb).float() / 255.0, torch.from_numpy(f.depth), directions)
        for f in frames
    ]
    poses = torch.stack([torch.from_numpy(f.pose_gt).float() for f in frames])
    poses[1:, :3, 3] += 0.01  # something for the poses' refinement to do
    bound = torch.tensor(scene_bound(build_scene(SCENE.scene, SCENE.seed)))
    field = new_field(config, bound, CPU)
    schedule = MappingSchedule(iterations=4, lr_factor=1.0, rays=config.mapping.rays)
    call = MappingCall(field, views, poses, [False, True, True], schedule)
    return call, MappingSettings(config.mapping, config.render, config.loss)


def test_auto_maps_in_a_process_on_a_cpu_and_in_a_thread_on_a_gpu() -> None:
    assert worker_kind("auto", CPU) == "process"
    assert worker_kind("auto", torch.device("cuda")) == "thread"
    assert worker_kind("thread", CPU) == "thread"
    with pytest.raises(ConfigError, match=r"concurrent_worker=thread or auto"):
        worker_kind("process", torch.device("cuda"))
    with pytest.raises(ConfigError, match=r"one of auto, thread, process"):
        worker_kind("fork", CPU)


@pytest.mark.slow
def test_a_process_maps_the_run_s_field_in_place_as_a_thread_does() -> None:
    call, settings = mapping_call()
    mapper = WindowMapper(settings, "off")
    before = {k: v.clone() for k, v in call.field.state_dict().items()}
    in_thread, _ = mapping_call()
    thread_generator = torch.Generator().manual_seed(7)
    process_generator = torch.Generator().manual_seed(7)
    thread, process = ThreadWorker(mapper, CPU), ProcessWorker(mapper)
    try:
        by_thread = thread.submit(in_thread, thread_generator).result()
        by_process = process.submit(call, process_generator).result()
        child = process.process
    finally:
        thread.close()
        process.close()
    assert child.poll() == 0 and process.process is None  # closed: the process is gone
    # the process changed the run's own tensors (the field was shared, not copied) ...
    assert not torch.equal(call.field.state_dict()[PLANES], before[PLANES])
    # ... exactly as the thread did, draws included
    for key, value in in_thread.field.state_dict().items():
        assert torch.equal(call.field.state_dict()[key], value), key
    assert torch.equal(by_process.poses, by_thread.poses)
    assert not torch.equal(by_process.poses[1:], call.poses[1:])  # the poses were refined
    assert torch.equal(process_generator.get_state(), thread_generator.get_state())


class FailingMapper:
    """Fails its call: raises a ValueError, or an error that cannot be pickled, or ends
    the process with exit code 3 (``how``: value, unpicklable, exit)."""

    def __init__(self, how: str) -> None:
        self.how = how

    def map(self, field, views, poses, optimise, schedule, generator) -> MappingResult:
        if self.how == "exit":
            os._exit(3)
        if self.how == "unpicklable":
            raise Unpicklable("odd error")
        raise ValueError("bad window")


class Unpicklable(Exception):
    def __reduce__(self):
        raise TypeError("not sent")


class SleepingMapper:
    """Takes ``seconds``, then gives the poses back and the process's id as the loss."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def map(self, field, views, poses, optimise, schedule, generator) -> MappingResult:
        time.sleep(self.seconds)
        return MappingResult(poses=poses.clone(), loss=torch.tensor(float(os.getpid())))


@pytest.mark.slow
def test_the_process_sends_errors_back_and_a_dead_one_is_named() -> None:
    call, _ = mapping_call()
    generator = torch.Generator()
    for how, error, message in (
        ("value", ValueError, "bad window"),
        ("unpicklable", RuntimeError, "Unpicklable: odd error"),  # its traceback's text
        ("exit", MappingProcessError, "ended \\(exit code 3\\) during a call"),
    ):
        worker = ProcessWorker(FailingMapper(how))
        try:
            with pytest.raises(error, match=message):
                worker.submit(call, generator).result(timeout=60)
        finally:
            worker.close()


@pytest.mark.slow
def test_ctrl_c_reaches_the_run_and_not_the_call_in_flight() -> None:
    call, _ = mapping_call()
    worker = ProcessWorker(SleepingMapper(1.0))
    try:
        future = worker.submit(call, torch.Generator())
        pid = worker.process.pid
        assert os.getpgid(pid) != os.getpgid(0)  # a terminal's Ctrl-C does not reach it
        for _ in range(3):  # sent to it all the same: while it starts, and while it maps
            for stop in (signal.SIGINT, signal.SIGTERM):
                os.kill(pid, stop)
            time.sleep(0.4)
        result = future.result(timeout=60)
        assert int(result.loss) == pid  # the call ran there and finished
        assert torch.equal(result.poses, call.poses)
        # the process is kept between calls
        again = worker.submit(call, torch.Generator()).result(timeout=60)
        assert int(again.loss) == pid
    finally:
        worker.close()


USER_SCRIPT = """
import os

import torch
from eslam.slam.mapping.workers import ProcessWorker
from tests.slam.test_mapping_workers import SleepingMapper, mapping_call

print("the script ran in", os.getpid())  # no __main__ guard: run again, it would say so
worker = ProcessWorker(SleepingMapper(0.0))
call, _ = mapping_call()
print("mapped in", int(worker.submit(call, torch.Generator()).result(timeout=60).loss))
worker.close()
"""


@pytest.mark.slow
def test_a_user_script_without_a_main_guard_runs_once(tmp_path: Path) -> None:
    script = tmp_path / "user_script.py"
    script.write_text(USER_SCRIPT)
    done = subprocess.run(
        [sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True, timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 2, lines  # the script ran once
    assert lines[0].startswith("the script ran in ") and lines[1].startswith("mapped in ")
    assert lines[0].split()[-1] != lines[1].split()[-1]  # and mapped in another process
