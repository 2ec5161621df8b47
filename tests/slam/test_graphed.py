"""compute.cuda_graphs: eager off CUDA (exactly the eager steps), graphs equal to eager.

The graphed tests run on CUDA with real graphs, and on the CPU with the capture
replaced by running the captured step (:class:`ReplayEagerly`): that checks the control
flow (when to capture, what a replay must be given, the in-place resets) everywhere,
and the capture itself where a GPU is.
"""

from __future__ import annotations

import copy
import dataclasses
import logging

import pytest
import torch

from eslam.config import ComputeConfig, ESLAMConfig
from eslam.slam import cuda_graphs as graphed
from eslam.slam.cuda_graphs import GraphedRenderTracker, WindowMapper, use_cuda_graphs
from eslam.slam.mapping.mapper import MappingSchedule, MappingSettings, map_window
from eslam.slam.mapping.warm_start import WarmStart
from eslam.slam.tracking.render import RenderTracker, TrackingSettings, track_frame
from eslam.slam.tracking.trackers import make_tracker
from tests.conftest import close_after_adam
from tests.slam.test_static_steps import moved, window_views
from tests.slam.test_steps import BOUND, _setup

needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


def test_auto_runs_eagerly_off_cuda_and_says_so_once(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(graphed, "_told", set())
    cpu = torch.device("cpu")
    with caplog.at_level(logging.INFO, logger="eslam"):
        assert not use_cuda_graphs("auto", cpu) and not use_cuda_graphs("auto", cpu)
        assert not use_cuda_graphs("off", torch.device("cuda"))
    said = [r.getMessage() for r in caplog.records if "cuda_graphs" in r.getMessage()]
    assert said == [
        "compute.cuda_graphs=auto: the iterations run eagerly (the device is cpu, not CUDA)"
    ]
    with pytest.raises(ValueError, match="cuda_graphs must be auto or off"):
        ComputeConfig(cuda_graphs="on")  # type: ignore[arg-type]


def test_auto_on_the_cpu_is_exactly_the_eager_path() -> None:
    """The trackers (render and hybrid) and the mapper that ``auto`` builds run the
    eager steps on the CPU: the same poses, losses and field, bit for bit."""
    config = dataclasses.replace(ESLAMConfig(), compute=ComputeConfig(cuda_graphs="auto"))
    for method in ("render", "hybrid"):
        tracking = dataclasses.replace(config.tracking, method=method)
        tracker = make_tracker(dataclasses.replace(config, tracking=tracking))
        render = tracker if method == "render" else tracker.render  # type: ignore[attr-defined]
        assert isinstance(render, GraphedRenderTracker)
    _, field, _ = _setup()
    settings = TrackingSettings(
        dataclasses.replace(config.tracking.render, rays=50, iterations=2),
        config.render,
        config.loss,
    )
    view = window_views(1)[0]
    ours = GraphedRenderTracker(settings, mode="auto").track(
        field, view, moved(0), torch.Generator().manual_seed(1)
    )
    eager = RenderTracker(settings).track(field, view, moved(0), torch.Generator().manual_seed(1))
    assert torch.equal(ours.pose, eager.pose) and torch.equal(ours.loss, eager.loss)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    schedule = MappingSchedule(2, 1.0, 64)
    views, poses = window_views(2), torch.stack([moved(0), moved(1)])
    other = copy.deepcopy(field)
    ours_map = WindowMapper(mapping, "auto").map(
        field, views, poses, [False, True], schedule, torch.Generator().manual_seed(2)
    )
    eager_map = map_window(
        other, views, poses, [False, True], mapping, schedule, torch.Generator().manual_seed(2)
    )
    assert torch.equal(ours_map.poses, eager_map.poses)
    assert all(map(torch.equal, field.parameters(), other.parameters()))


class ReplayEagerly:
    """Stands in for CapturedIteration on the CPU: a "replay" runs the step eagerly."""

    def __init__(self, step, generator: torch.Generator, keep=()) -> None:
        self.step, self.generator = step, generator

    def replay(self) -> None:
        self.step(self.generator)


@pytest.fixture(params=["cpu", pytest.param("cuda", marks=[needs_cuda, pytest.mark.cuda])])
def device(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """cuda: real graphs; cpu: graphs switched on, the capture replaced (module doc)."""
    if request.param == "cpu":
        monkeypatch.setattr(graphed, "CapturedIteration", ReplayEagerly)
        monkeypatch.setattr(graphed, "use_cuda_graphs", lambda mode, *args: mode == "auto")
    return request.param


def _close(a: torch.Tensor, b: torch.Tensor) -> bool:
    """Equal within float tolerance (capturable Adam forms its step in float32)."""
    return bool(torch.allclose(a, b, rtol=1e-4, atol=1e-5))


def test_graphed_tracking_equals_the_eager_tracker(device: str) -> None:
    config, field, _ = _setup(device)
    settings = TrackingSettings(
        dataclasses.replace(config.tracking.render, rays=100, iterations=3),
        config.render,
        config.loss,
    )
    tracker = GraphedRenderTracker(settings, mode="auto")
    eager_generator = torch.Generator(device=device).manual_seed(3)
    graph_generator = torch.Generator(device=device).manual_seed(3)
    for k, view in enumerate(window_views(3, device)):
        start = moved(k, device)
        eager = track_frame(field, view, start, settings, eager_generator)
        ours = tracker.track(field, view, start, graph_generator)
        assert _close(ours.pose, eager.pose) and _close(ours.loss, eager.loss)
    assert tracker.graphs.captures == 1  # one capture, replayed for every frame
    assert torch.equal(graph_generator.get_state(), eager_generator.get_state())


def test_graphed_mapping_equals_map_window_and_recaptures(device: str) -> None:
    """Windows of 3, 2 and 3 keyframes (a graph per size, kept), then plane growth (all
    captured again): every call leaves the field, poses and generator where map_window
    does."""
    config, eager_field, _ = _setup(device)
    graph_field = copy.deepcopy(eager_field)
    settings = MappingSettings(config.mapping, config.render, config.loss)
    mapper = WindowMapper(settings, "auto")
    views = window_views(3, device)
    poses = torch.stack([moved(k, device) for k in range(3)])
    eager_generator = torch.Generator(device=device).manual_seed(5)
    graph_generator = torch.Generator(device=device).manual_seed(5)
    every = [False, True, True]
    calls = [  # (window rows, poses refined, schedule, captures so far)
        ([0, 1, 2], every, MappingSchedule(3, 5.0, 96, lr_decay=0.3), 1),
        ([1, 2], [False, True], MappingSchedule(2, 1.0, 64), 2),  # another window size
        ([0, 1, 2], every, MappingSchedule(2, 1.0, 96), 2),  # its graph kept: replayed
        ([0, 1, 2], [False, False, False], MappingSchedule(2, 1.0, 96), 2),
        ([0, 1, 2], every, MappingSchedule(2, 1.0, 96), 3),  # after plane growth
    ]
    for call, (rows, optimise, schedule, captures) in enumerate(calls):
        if call == 4:
            wider = BOUND.clone()
            wider[0, 1] = 2.0
            for field in (eager_field, graph_field):
                assert field.grow(wider, torch.Generator(device=device).manual_seed(7))
        window = [views[r] for r in rows]
        eager = map_window(
            eager_field, window, poses[rows], optimise, settings, schedule, eager_generator
        )
        ours = mapper.map(graph_field, window, poses[rows], optimise, schedule, graph_generator)
        assert mapper.captures == captures
        assert _close(ours.poses, eager.poses) and _close(ours.loss, eager.loss)
        for a, b in zip(graph_field.parameters(), eager_field.parameters(), strict=True):
            assert close_after_adam(a.detach(), b.detach(), rtol=1e-4, atol=1e-5)
    assert torch.equal(graph_generator.get_state(), eager_generator.get_state())


def test_a_failed_capture_falls_back_to_the_eager_steps(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def refuse(*args, **kwargs):
        raise RuntimeError("operation not permitted when stream is capturing")

    monkeypatch.setattr(graphed, "CapturedIteration", refuse)
    monkeypatch.setattr(graphed, "use_cuda_graphs", lambda mode, *args: mode == "auto")
    config, field, _ = _setup()
    other = copy.deepcopy(field)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    mapper = WindowMapper(mapping, "auto")
    views, poses = window_views(2), torch.stack([moved(0), moved(1)])
    schedule = MappingSchedule(2, 1.0, 64)
    with caplog.at_level(logging.WARNING, logger="eslam"):
        ours = mapper.map(
            field, views, poses, [False, True], schedule, torch.Generator().manual_seed(2)
        )
    eager = map_window(
        other, views, poses, [False, True], mapping, schedule, torch.Generator().manual_seed(2)
    )
    assert mapper.failed and "capturing an iteration failed" in caplog.text
    assert torch.equal(ours.poses, eager.poses)
    assert all(map(torch.equal, field.parameters(), other.parameters()))


def test_graphed_first_call_runs_the_warm_start_as_map_window(device: str) -> None:
    """A first call with a TSDF warm start (the CPU preset's first frame): the warm start
    runs before the graphed rendering steps, and field, poses and generator end where
    map_window leaves them (without it the field would differ)."""
    config, eager_field, _ = _setup(device)
    graph_field = copy.deepcopy(eager_field)
    settings = MappingSettings(config.mapping, config.render, config.loss)
    views = window_views(1, device)
    poses = moved(0, device)[None]
    schedule = MappingSchedule(2, 2.0, 64, warm_start=WarmStart(steps=3, points=200))
    eager_generator = torch.Generator(device=device).manual_seed(9)
    graph_generator = torch.Generator(device=device).manual_seed(9)
    eager = map_window(eager_field, views, poses, [False], settings, schedule, eager_generator)
    mapper = WindowMapper(settings, "auto")
    ours = mapper.map(graph_field, views, poses, [False], schedule, graph_generator)
    assert mapper.captures == 1
    assert _close(ours.poses, eager.poses) and _close(ours.loss, eager.loss)
    for a, b in zip(graph_field.parameters(), eager_field.parameters(), strict=True):
        assert _close(a.detach(), b.detach())
    assert torch.equal(graph_generator.get_state(), eager_generator.get_state())
