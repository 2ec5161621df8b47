"""The graph-ready iterations equal the eager ones (run eagerly, on the CPU)."""

from __future__ import annotations

import copy
import dataclasses

import torch

from eslam.field.scene_field import SceneField
from eslam.geometry.pose import se3_exp
from eslam.render.rays import camera_directions
from eslam.slam.mapping.mapper import MappingSchedule, MappingSettings, map_window
from eslam.slam.static_steps import (
    StaticMapping,
    StaticTracking,
    reset_adam,
    run_mapping,
    run_tracking,
)
from eslam.slam.tracking.render import TrackingSettings, track_frame
from eslam.slam.views import View, make_view
from tests.conftest import close_after_adam
from tests.slam.test_steps import CAMERA, _setup


def window_views(count: int, device: str = "cpu") -> list[View]:
    """``count`` different views of the test camera (depth 0.7 m and up, random colour)."""
    views = []
    for k in range(count):
        depth = torch.full((30, 40), 0.7 + 0.1 * k, device=device)
        depth[:, : 5 + 3 * k] = 0.0
        rgb = torch.rand(30, 40, 3, generator=torch.Generator().manual_seed(10 + k)).to(device)
        views.append(make_view(rgb, depth, camera_directions(CAMERA, device), border=2))
    return views


def moved(k: int, device: str = "cpu") -> torch.Tensor:
    """A pose a few centimetres and degrees from the identity, different for each ``k``."""
    twist = torch.tensor([0.01, -0.02, 0.015, 0.02, -0.01, 0.03], device=device) * (k + 1)
    return se3_exp(twist).float()


def close(a: torch.Tensor, b: torch.Tensor) -> bool:
    return bool(torch.allclose(a, b, rtol=1e-5, atol=1e-6))


def test_static_tracking_equals_the_eager_tracker() -> None:
    """Two frames on one set of buffers (the second after an in-place reset) give the
    poses, losses and random draws of two fresh eager trackers."""
    config, field, _ = _setup()
    tracker = dataclasses.replace(config.tracking.render, rays=100, iterations=3)
    settings = TrackingSettings(tracker, config.render, config.loss)
    views = window_views(2)
    eager_generator = torch.Generator().manual_seed(3)
    static_generator = torch.Generator().manual_seed(3)
    static = StaticTracking(settings, views[0])
    for k, view in enumerate(views):
        start = moved(k)
        eager = track_frame(field, view, start, settings, eager_generator)
        ours = run_tracking(
            static, field, view, start, lambda: static.step(field, static_generator)
        )
        assert not torch.equal(eager.pose, start)  # the tracker moved the pose
        assert close(ours.pose, eager.pose) and close(ours.loss, eager.loss)
    assert torch.equal(static_generator.get_state(), eager_generator.get_state())


def _field_parameters(field: SceneField) -> list[torch.Tensor]:
    return [p.detach() for p in field.parameters()]


def test_static_mapping_equals_map_window() -> None:
    """Windows of 3, then 2, then 3 keyframes in 4 slots (one optimiser, reset in place),
    with poses refined or all held: the static iterations leave the field, the poses and
    the loss where map_window does, and draw the same numbers."""
    config, eager_field, _ = _setup()
    static_field = copy.deepcopy(eager_field)
    settings = MappingSettings(config.mapping, config.render, config.loss)
    views = window_views(3)
    poses = torch.stack([moved(k) for k in range(3)])
    calls = [
        ([0, 1, 2], [False, True, True], MappingSchedule(3, 5.0, 96, lr_decay=0.3)),
        ([1, 2], [False, True], MappingSchedule(2, 1.0, 64)),
        ([0, 1, 2], [False, False, False], MappingSchedule(2, 1.0, 96)),
    ]
    eager_generator = torch.Generator().manual_seed(5)
    static_generator = torch.Generator().manual_seed(5)
    mapping = StaticMapping(settings, static_field, views[0], slots=4)
    for rows, optimise, schedule in calls:
        window = [views[r] for r in rows]
        size = len(rows)
        assert mapping.fits(static_field, window)
        eager = map_window(
            eager_field, window, poses[rows], optimise, settings, schedule, eager_generator
        )
        ours = run_mapping(
            mapping,
            window,
            poses[rows],
            optimise,
            schedule,
            lambda n=size, s=schedule: mapping.step(static_field, static_generator, s.rays, n),
        )
        assert ours.poses.shape == eager.poses.shape
        assert close(ours.poses, eager.poses) and close(ours.loss, eager.loss)
        held = [i for i, flag in enumerate(optimise) if not flag]
        assert torch.equal(ours.poses[held], poses[rows][held])  # held rows exactly
        for a, b in zip(
            _field_parameters(static_field), _field_parameters(eager_field), strict=True
        ):
            assert close_after_adam(a, b, rtol=1e-5, atol=1e-6)
    untouched = _field_parameters(_setup()[1])
    assert not all(map(torch.equal, _field_parameters(eager_field), untouched))  # it mapped
    assert torch.equal(static_generator.get_state(), eager_generator.get_state())


def test_static_mapping_needs_new_buffers_after_plane_growth() -> None:
    config, field, view = _setup()
    settings = MappingSettings(config.mapping, config.render, config.loss)
    mapping = StaticMapping(settings, field, view, slots=2)
    assert mapping.fits(field, [view, view]) and not mapping.fits(field, [view] * 3)
    field.grow(torch.tensor([[-1.0, 3.0], [-1.0, 1.0], [-1.0, 1.5]]))
    assert not mapping.fits(field, [view, view])  # the planes were replaced


def test_reset_adam_gives_a_new_optimisers_step() -> None:
    """After a reset in place, a step equals the first step of a new Adam."""
    start = torch.tensor([1.0, -2.0, 0.5])
    used = start.clone().requires_grad_(True)
    optimiser = torch.optim.Adam([used], lr=0.1)
    for _ in range(3):
        optimiser.zero_grad()
        (used.square().sum()).backward()
        optimiser.step()
    with torch.no_grad():
        used.copy_(start)
    reset_adam(optimiser)
    fresh = start.clone().requires_grad_(True)
    new = torch.optim.Adam([fresh], lr=0.1)
    for variable, adam in ((used, optimiser), (fresh, new)):
        adam.zero_grad()
        (variable * torch.tensor([3.0, 1.0, -2.0])).sum().backward()
        adam.step()
    assert torch.equal(used, fresh)
