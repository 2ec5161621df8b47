"""Honest reporting of a lost camera: metrics.json gives the longest run of failed
frames and whether the run ended tracked, log.txt says where a loss ends, and the
progress bar shows the camera as lost while it is."""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from eslam.slam.run.observers import FrameDone, RunStart
from eslam.slam.run.progress import ProgressObserver
from eslam.slam.session import run_slam
from eslam.slam.state import failed_stretch, longest_failed_run
from eslam.slam.tracking.base import TrackingQuality, TrackingResult
from eslam.slam.tracking.trackers import TRACKERS
from tests.conftest import TINY_FRAMES, tiny_config

OK = [3.0, 0.9, 0.002, 0.0, float("nan"), float("nan"), 0.0, float("nan")]
FAILED = [3.0, 0.1, 0.05, 1.0, float("nan"), float("nan"), 0.0, float("nan")]
UNJUDGED = [float("nan")] * 8


def test_runs_of_failed_rows() -> None:
    rows = [UNJUDGED, OK, FAILED, FAILED, OK, FAILED, FAILED, FAILED, UNJUDGED, FAILED]
    assert longest_failed_run(rows) == 3
    assert failed_stretch(rows) == 1  # a frame without a judgement ends a stretch
    assert failed_stretch(rows[:8]) == 3 and failed_stretch(rows[:5]) == 0
    assert longest_failed_run([]) == 0 and failed_stretch([]) == 0


class FailsFrom:
    """The rendering tracker, reporting the frames in ``FAILING`` as failed."""

    FAILING: frozenset[int] = frozenset()

    def __init__(self, config) -> None:
        self.real = TRACKERS.make("render", config)
        self.frame = 0

    def track(self, field, view, initial_pose, generator):
        self.frame += 1  # frame 0 is not tracked: call k tracks frame k
        result = self.real.track(field, view, initial_pose, generator)
        failed = self.frame in self.FAILING
        quality = TrackingQuality(3, 0.1 if failed else 0.9, 0.05 if failed else 0.002, failed)
        return TrackingResult(result.pose, result.loss, quality)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("failing", "longest", "ended_tracked"),
    [(range(4, 8), 4, True), (range(9, TINY_FRAMES), TINY_FRAMES - 9, False)],
)
def test_a_loss_is_reported_in_metrics_and_log(
    tiny_sequence: Path,
    tmp_path: Path,
    register,
    monkeypatch: pytest.MonkeyPatch,
    failing: range,
    longest: int,
    ended_tracked: bool,
) -> None:
    register(TRACKERS, "fails_from", FailsFrom)
    monkeypatch.setattr(FailsFrom, "FAILING", frozenset(failing))
    # recovery off: the fake tracker counts its calls as frames
    config = tiny_config(tiny_sequence, "output.mesh=false", "tracking.recovery.enabled=false")
    config = dataclasses.replace(
        config, tracking=dataclasses.replace(config.tracking, method="fails_from")
    )
    result = run_slam(config, tmp_path / "run")
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics == {**metrics, **result.metrics}
    assert metrics["tracking_failures"] == len(failing)
    assert metrics["tracking_failed_longest_run"] == longest
    assert metrics["tracking_ended_tracked"] is ended_tracked
    log = (tmp_path / "run" / "log.txt").read_text()
    first, last = failing[0], failing[-1]
    if ended_tracked:
        assert (
            f"frame {last + 1}: tracked again after {longest} failed frames ({first}-{last})" in log
        )
    else:
        assert "tracked again" not in log


def test_the_progress_bar_shows_the_camera_lost_while_it_is() -> None:
    rows: list[list[float]] = []
    state = SimpleNamespace(tracking_quality=rows, next_frame=0, components={})
    bar = ProgressObserver(True, file=io.StringIO())
    start = RunStart(None, Path("."), state, torch.device("cpu"), "test", 6, False)
    bar.on_start(start)
    shown = []
    for index, row in enumerate([OK, FAILED, FAILED, OK]):
        rows.append(row)
        quality = TrackingQuality(3, row[1], row[2], bool(row[3]))
        bar.on_frame(FrameDone(index, torch.eye(4), True, quality, False, 0.0, 0.0))
        shown.append(bar.postfix.get("lost_frames"))
    bar.close()
    assert shown == [None, "1", "2", None]
