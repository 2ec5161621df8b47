"""The optimisation steps: drawn ahead, pure in between, free of host syncs, compilable."""

from __future__ import annotations

import contextlib
import dataclasses
from types import SimpleNamespace

import pytest
import torch

from eslam.config import ESLAMConfig
from eslam.field.scene_field import SceneField
from eslam.render.rays import camera_directions
from eslam.render.renderer import render_rays
from eslam.slam.mapping.mapper import (
    MappingSchedule,
    MappingSettings,
    WindowPoses,
    map_window,
    mapping_loss,
    mapping_optimiser,
    mapping_schedule,
    mapping_step,
)
from eslam.slam.tracking.render import (
    PoseVariables,
    TrackingSettings,
    frozen,
    keep_best,
    pose_optimiser,
    tracking_loss,
    tracking_step,
)
from eslam.slam.views import (
    draw_rays,
    make_view,
    pixels_from_uniforms,
    sample_view_rays,
    view_rays,
)
from eslam.stages import PREFIX, STAGES, stage, stage_totals
from eslam.types import Intrinsics

CAMERA = Intrinsics(width=40, height=30, fx=30.0, fy=30.0, cx=19.5, cy=14.5)
BOUND = torch.tensor([[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.5]])


def _setup(device: str = "cpu"):
    config = ESLAMConfig()
    field = SceneField(config.field, BOUND, torch.Generator().manual_seed(0)).to(device)
    depth = torch.full((30, 40), 0.8, device=device)
    depth[:, :10] = 0.0  # invalid depth: never sampled
    rgb = torch.rand(30, 40, 3, generator=torch.Generator().manual_seed(1)).to(device)
    view = make_view(rgb, depth, camera_directions(CAMERA, device), border=2)
    return config, field, view


def test_views_sample_only_valid_pixels_inside_the_border() -> None:
    _, _, view = _setup()
    assert view.sampleable_pixels() == (30 - 4) * (40 - 10 - 2)
    uniforms = torch.linspace(0.0, 0.999999, 5000)
    pixels = pixels_from_uniforms(view, uniforms)
    u, v = pixels % 40, pixels // 40
    assert bool(((u >= 10) & (u < 38) & (v >= 2) & (v < 28)).all())
    assert len(torch.unique(pixels)) == view.sampleable_pixels()  # every one reachable


def test_drawing_ahead_gives_the_renderers_own_draws() -> None:
    config, field, view = _setup()
    generator = torch.Generator().manual_seed(6)
    rays = sample_view_rays(view, torch.eye(4), 300, generator)
    inline = render_rays(field, rays, config.render, True, generator)
    draws = draw_rays(1, 300, config.render, torch.Generator().manual_seed(6), torch.device("cpu"))
    rays = view_rays(view, torch.eye(4), pixels_from_uniforms(view, draws.pixels[0]))
    ahead = render_rays(field, rays, config.render, True, noise=draws.jitter)
    assert torch.equal(inline.z_vals, ahead.z_vals) and torch.equal(inline.depth, ahead.depth)


def test_keep_best_chooses_on_the_device() -> None:
    best = torch.tensor(2.0), torch.zeros(4, 4)
    loss, pose = keep_best(*best, torch.tensor(1.0), torch.ones(4, 4))
    assert float(loss) == 1.0 and bool((pose == 1).all())
    loss, pose = keep_best(loss, pose, torch.tensor(1.0), torch.full((4, 4), 7.0))
    assert bool((pose == 1).all())  # ties keep the earlier pose


@pytest.mark.slow
def test_losses_compile_as_one_graph() -> None:
    """torch.compile(fullgraph=True) traces the tracking and mapping losses without a
    graph break (backend "eager": the trace, not a C++ build). The random draws and the
    optimiser step stay outside (a torch.Generator argument and Optimizer.zero_grad /
    backward() are graph breaks by design in dynamo), which is why the steps draw ahead."""
    torch._dynamo.reset()
    config, field, view = _setup()
    generator = torch.Generator().manual_seed(0)
    settings = TrackingSettings(config.tracking.render, config.render, config.loss)
    variables = PoseVariables.from_pose(torch.eye(4))
    draws = draw_rays(1, 200, config.render, generator, torch.device("cpu"))
    compiled = torch.compile(tracking_loss, fullgraph=True, backend="eager")
    with frozen(field):
        eager_loss, _ = tracking_loss(field, view, variables, draws, settings)
        traced_loss, _ = compiled(field, view, variables, draws, settings)
    assert torch.equal(eager_loss, traced_loss)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    window = WindowPoses.create(torch.eye(4).repeat(2, 1, 1), [False, True])
    draws = draw_rays(2, 100, config.render, generator, torch.device("cpu"))
    compiled_mapping = torch.compile(mapping_loss, fullgraph=True, backend="eager")
    eager = mapping_loss(field, [view, view], window, draws, mapping)
    assert torch.equal(eager, compiled_mapping(field, [view, view], window, draws, mapping))
    noisy = MappingSettings(
        dataclasses.replace(config.mapping, weigh_depth_noise=True), config.render, config.loss
    )
    ramp = view.depth.reshape(30, 40) * torch.linspace(0.5, 2.0, 40)  # depths 0.4-1.6 m
    sloped = make_view(view.rgb.reshape(30, 40, 3), ramp, camera_directions(CAMERA), border=2)
    views = [view, sloped]
    plain_loss = mapping_loss(field, views, window, draws, mapping)
    eager_noisy = mapping_loss(field, views, window, draws, noisy)
    assert abs(eager_noisy.item() - plain_loss.item()) > 1e-3 * abs(plain_loss.item())
    assert torch.equal(eager_noisy, compiled_mapping(field, views, window, draws, noisy))


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_steps_do_not_sync_with_the_device() -> None:
    config, field, view = _setup("cuda")
    generator = torch.Generator(device="cuda").manual_seed(0)
    settings = TrackingSettings(config.tracking.render, config.render, config.loss)
    variables = PoseVariables.from_pose(torch.eye(4, device="cuda"))
    optimiser = pose_optimiser(variables, config.tracking.render)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    window = WindowPoses.create(torch.eye(4, device="cuda").repeat(2, 1, 1), [False, True])
    map_optimiser = mapping_optimiser(field, window, config.mapping, 1.0)
    for _ in range(2):  # the first call of each may initialise lazily
        with frozen(field):
            tracking_step(field, view, variables, optimiser, settings, generator)
        mapping_step(field, [view, view], window, map_optimiser, mapping, generator)
    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("error")
    try:
        with frozen(field):
            tracking_step(field, view, variables, optimiser, settings, generator)
        mapping_step(field, [view, view], window, map_optimiser, mapping, generator)
    finally:
        torch.cuda.set_sync_debug_mode("default")


def test_mapping_schedules() -> None:
    config = ESLAMConfig().mapping
    first = mapping_schedule(config, first=True)
    assert (first.iterations, first.lr_factor, first.rays) == (1000, 5.0, 4000)
    assert [first.lr_scale(s) for s in (0, 500, 999)] == [1.0, 1.0, 1.0]  # release: constant
    later = mapping_schedule(config, first=False)
    assert (later.iterations, later.lr_factor, later.rays, later.lr_decay) == (15, 1.0, 4000, 1.0)
    fast = dataclasses.replace(config, first_iterations=101, first_rays=8000, first_lr_decay=0.1)
    schedule = mapping_schedule(fast, first=True)
    assert schedule.rays == 8000
    assert schedule.lr_scale(0) == 1.0 and schedule.lr_scale(100) == pytest.approx(0.1)
    assert schedule.lr_scale(50) == pytest.approx(0.55)  # halfway down the cosine
    with pytest.raises(ValueError, match="first_lr_decay"):
        dataclasses.replace(config, first_lr_decay=0.0)


def test_map_window_decays_the_map_learning_rates(monkeypatch: pytest.MonkeyPatch) -> None:
    config, field, view = _setup()
    settings = MappingSettings(config.mapping, config.render, config.loss)
    seen: list[float] = []
    original = torch.optim.Adam.step

    def spy(self, *args, **kwargs):
        seen.append(self.param_groups[0]["lr"])
        return original(self, *args, **kwargs)

    monkeypatch.setattr(torch.optim.Adam, "step", spy)
    map_window(
        field,
        [view],
        torch.eye(4)[None],
        [False],
        settings,
        MappingSchedule(iterations=3, lr_factor=5.0, rays=64, lr_decay=0.2),
        torch.Generator().manual_seed(0),
    )
    start = 5.0 * config.mapping.lr_planes
    assert seen == pytest.approx([start, start * 0.6, start * 0.2])


def test_every_stage_of_both_steps_is_a_profiler_region(monkeypatch: pytest.MonkeyPatch) -> None:
    """bench_core's breakdown reads these regions: each stage must run inside the steps.

    The regions are recorded by replacing torch.profiler.record_function (a real
    profiler takes seconds to start); stage_totals is checked on events like the
    profiler's."""
    entered: list[str] = []

    class Recorder(contextlib.nullcontext):
        def __init__(self, name: str) -> None:
            super().__init__()
            entered.append(name)

    monkeypatch.setattr(torch.profiler, "record_function", Recorder)
    config, field, view = _setup()
    generator = torch.Generator().manual_seed(0)
    tracker = dataclasses.replace(config.tracking.render, rays=50)
    settings = TrackingSettings(tracker, config.render, config.loss)
    variables = PoseVariables.from_pose(torch.eye(4))
    optimiser = pose_optimiser(variables, tracker)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    window = WindowPoses.create(torch.eye(4).repeat(2, 1, 1), [False, True])
    map_optimiser = mapping_optimiser(field, window, config.mapping, 1.0)
    with frozen(field):
        tracking_step(field, view, variables, optimiser, settings, generator)
    assert {PREFIX + name for name in STAGES} <= set(entered)
    entered.clear()
    mapping_step(field, [view, view], window, map_optimiser, mapping, generator, rays=50)
    assert {PREFIX + name for name in STAGES} <= set(entered)
    events = [SimpleNamespace(name=name, cpu_time_total=10.0) for name in entered]
    events.append(SimpleNamespace(name="aten::mm", cpu_time_total=99.0))
    totals = stage_totals(events)
    assert totals["backward"] == 10.0 and totals["ray sampling"] >= 20.0
    with pytest.raises(ValueError, match="unknown stage"):
        stage("everything")


def test_a_compiled_tracking_loss_tracks_as_the_eager_one() -> None:
    """compute.compile=tracking: the trackers get a compiled loss (render and hybrid; off
    keeps the eager one), and tracking with a compiled loss gives the eager pose. The
    test compiles with the aot_eager backend (the same trace and autograd split as
    inductor, without a C++ build; inductor's speed is benchmarks/bench_compile.py's)."""
    from eslam.config import ComputeConfig
    from eslam.slam.tracking.render import compiled_tracking_loss, track_frame, tracking_loss
    from eslam.slam.tracking.trackers import make_tracker

    config, field, view = _setup()
    compiled = dataclasses.replace(config, compute=ComputeConfig(compile="tracking"))
    for method in ("render", "hybrid"):
        tracking = dataclasses.replace(config.tracking, method=method)
        on = make_tracker(dataclasses.replace(compiled, tracking=tracking))
        off = make_tracker(dataclasses.replace(config, tracking=tracking))
        on, off = (t if method == "render" else t.render for t in (on, off))  # type: ignore[attr-defined]
        assert on.loss_function is not tracking_loss and off.loss_function is tracking_loss
    with pytest.raises(ValueError, match="compile must be off or tracking"):
        ComputeConfig(compile="all")  # type: ignore[arg-type]

    torch._dynamo.reset()
    settings = TrackingSettings(
        dataclasses.replace(config.tracking.render, rays=100, iterations=3),
        config.render,
        config.loss,
    )
    start = torch.eye(4)
    start[:3, 3] = torch.tensor([0.01, -0.02, 0.01])
    eager = track_frame(field, view, start, settings, torch.Generator().manual_seed(4))
    ours = track_frame(
        field,
        view,
        start,
        settings,
        torch.Generator().manual_seed(4),
        compiled_tracking_loss(backend="aot_eager"),
    )
    assert torch.allclose(ours.pose, eager.pose, atol=1e-6)
    assert torch.allclose(ours.loss, eager.loss, rtol=1e-5)
    assert not torch.equal(eager.pose, start)  # the pose moved: the comparison means something
    calls = []

    def counted(*args):
        calls.append(1)
        return tracking_loss(*args)

    track_frame(field, view, start, settings, torch.Generator().manual_seed(4), counted)
    assert len(calls) == 3  # the loss given is the one every iteration uses
