"""The progress of a run and how it ends on screen and in log.txt (issue 15, item 6)."""

from __future__ import annotations

import io
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
import tqdm.std

from eslam.errors import RunInterrupted
from eslam.slam.run.observers import FrameDone, MappingStep, RunObserverBase, RunStart
from eslam.slam.run.progress import ProgressObserver
from eslam.slam.session import run_slam
from tests.conftest import tiny_config

FIRST_ITERATIONS = 20


class Clock:
    """A stand-in for time.time that moves only when told."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def _start(frames: int) -> RunStart:
    state = SimpleNamespace(
        next_frame=0,
        trajectory=SimpleNamespace(gt_poses=lambda: None),
        tracking_quality=[],
        components={},
    )
    return RunStart(None, Path("run"), state, torch.device("cpu"), "seq", frames, False)


def _frame(index: int) -> FrameDone:
    return FrameDone(index, torch.eye(4), True, None, False, 0.0, 0.0)


def test_the_eta_ignores_the_first_frame(monkeypatch: pytest.MonkeyPatch) -> None:
    """A first frame of 100 s then 1 s per frame: the ETA said ~30 min for ~1.5 min."""
    clock = Clock()
    monkeypatch.setattr(tqdm.std, "time", clock)
    progress = ProgressObserver(True, io.StringIO())
    progress.on_start(_start(100))
    clock.now += 100.0
    progress.on_frame(_frame(0))
    for index in range(1, 6):
        clock.now += 1.0
        progress.on_frame(_frame(index))
    info = progress.bar.format_dict
    remaining_s = (info["total"] - info["n"]) / info["rate"]
    assert info["n"] == 6 and 94 * 0.8 < remaining_s < 94 * 1.25
    progress.close()


def test_the_first_mapping_call_has_its_own_bar() -> None:
    out = io.StringIO()
    progress = ProgressObserver(True, out)
    progress.on_start(_start(10))
    progress.on_mapping_step(MappingStep(0, 0, 100, first=True))
    progress.on_mapping_step(MappingStep(0, 50, 100, first=True))
    assert progress.mapping_bar is not None and progress.mapping_bar.n == 50
    progress.on_mapping_step(MappingStep(0, 100, 100, first=True))
    assert progress.mapping_bar is None  # closed (and erased) when the call is done
    progress.on_mapping_step(MappingStep(3, 0, 6, first=False))
    assert progress.mapping_bar is None  # later calls are short: no second bar
    progress.close()
    assert "mapping frame 0 (the map's first call)" in out.getvalue()


def test_the_bar_shows_the_mapping_queue_of_a_run_that_maps_beside() -> None:
    out = io.StringIO()
    progress = ProgressObserver(True, out)
    start = _start(10)
    progress.on_start(start)
    progress.on_frame(_frame(0))
    assert "map_queue" not in progress.postfix  # mapping in turn: no queue
    start.state.components["concurrent_mapping"] = {"queue": 2}
    progress.on_frame(_frame(1))
    assert progress.postfix["map_queue"] == "2"
    progress.close()


class Recorder(RunObserverBase):
    def __init__(self) -> None:
        self.steps: list[MappingStep] = []

    def on_mapping_step(self, step: MappingStep) -> None:
        self.steps.append(step)


def test_the_loop_reports_every_mapping_iteration(tiny_sequence: Path, tmp_path: Path) -> None:
    """The first frame mapped for minutes with no sign of life."""
    recorder = Recorder()
    config = tiny_config(tiny_sequence, f"mapping.first_iterations={FIRST_ITERATIONS}")
    run_slam(config, tmp_path / "run", stop_after=4, observers=[recorder])
    first = [step for step in recorder.steps if step.first]
    assert [step.done for step in first] == list(range(FIRST_ITERATIONS + 1))
    assert {(step.index, step.iterations) for step in first} == {(0, FIRST_ITERATIONS)}
    later = [step for step in recorder.steps if not step.first]
    assert {step.index for step in later} == {3}  # mapping.every=3
    assert [step.done for step in later] == list(range(config.mapping.iterations + 1))


class StopIn(RunObserverBase):
    """Raises ``error`` in the event ``when`` (on_start, on_frame or on_finish)."""

    def __init__(self, when: str, error: BaseException) -> None:
        setattr(self, when, self._raise)
        self.error = error

    def _raise(self, event: object) -> None:
        raise self.error


@pytest.mark.parametrize("when", ["on_start", "on_finish"])
def test_an_interruption_at_the_start_or_end_closes_the_bar_and_is_logged(
    when: str, tiny_sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C while the mesh was extracted left the bar open: "interrupted" was printed
    on its line, the bar redrawn under it, and log.txt said nothing."""
    config = tiny_config(tiny_sequence, "output.progress=true", "mapping.first_iterations=10")
    run = tmp_path / "run"
    with pytest.raises(RunInterrupted) as stopped:
        run_slam(config, run, stop_after=2, observers=[StopIn(when, KeyboardInterrupt())])
    err = capsys.readouterr().err
    assert "frame" in err and err.endswith("\n")  # the bar was drawn, then closed
    last = (run / "log.txt").read_text().splitlines()[-1]
    assert "ERROR stopped: interrupted" in last and f"eslam resume {run}" in last
    assert f"eslam resume {run}" in str(stopped.value)


def test_a_bug_leaves_its_traceback_in_log_txt(tiny_sequence: Path, tmp_path: Path) -> None:
    config = tiny_config(tiny_sequence, "mapping.first_iterations=10")
    run = tmp_path / "run"
    with pytest.raises(ZeroDivisionError):
        run_slam(config, run, stop_after=2, observers=[StopIn("on_frame", ZeroDivisionError())])
    log = (run / "log.txt").read_text()
    assert "ERROR stopped by an error" in log and "Traceback" in log
    assert f"eslam resume {run}" in log  # the note saying where the frames are
