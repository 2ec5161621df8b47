"""The TSDF warm start (eslam/slam/mapping/warm_start.py): the first frame's, a window's."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from eslam.config import ESLAMConfig, LossConfig
from eslam.field.scene_field import SceneField
from eslam.losses import sdf_loss_terms
from eslam.render.rays import camera_directions
from eslam.slam.mapping.mapper import (
    MappingSchedule,
    MappingSettings,
    map_window,
    mapping_schedule,
    warm_start_window,
)
from eslam.slam.mapping.warm_start import (
    WarmStart,
    projective_tsdf,
    tsdf_warm_start,
    tsdf_warm_start_views,
    warm_start_points,
)
from eslam.slam.views import make_view
from tests.slam.test_steps import BOUND, CAMERA

T = 0.06


def _setup():
    config = ESLAMConfig()
    coarse = dataclasses.replace(  # the tiny settings' planes: a quick test
        config.field, geometry_resolution=(0.24, 0.12), appearance_resolution=(0.24, 0.12)
    )
    field = SceneField(coarse, BOUND, torch.Generator().manual_seed(0))
    depth = torch.full((30, 40), 0.8)
    depth[:, :10] = 0.0  # invalid depth: never sampled
    rgb = torch.rand(30, 40, 3, generator=torch.Generator().manual_seed(1))
    return config, field, make_view(rgb, depth, camera_directions(CAMERA))


def test_the_targets_zero_the_papers_sdf_loss() -> None:
    """s* is the minimiser of every SDF term where the loss has one (z <= D + T), and its
    written-out values: 1 in free space, (D - z) / T in the band."""
    depth = torch.tensor([1.0, 1.0, 1.0, 1.0, 2.0])
    z = torch.tensor([0.3, 1.0 - T, 1.0 - 0.2 * T, 1.0 + T, 2.0 + 0.5 * T])
    target = projective_tsdf(z, depth, T)
    assert torch.allclose(target, torch.tensor([1.0, 1.0, 0.2, -1.0, -0.5]))
    for single_band in (False, True):
        terms = sdf_loss_terms(
            target[:, None], z[:, None], depth, T, LossConfig(single_band=single_band)
        )
        assert all(float(term) < 1e-12 for term in terms)


def test_points_lie_on_the_rays_in_the_band_or_in_front_of_it() -> None:
    _, _, view = _setup()
    pose = torch.eye(4)
    points, target = warm_start_points(view, pose, 400, T, 0.25, torch.Generator().manual_seed(0))
    z = points[:, 2]  # identity pose: the camera's optical axis is world z, depth 0.8
    band, free = slice(0, 100), slice(100, 400)
    assert bool(((z[band] - 0.8).abs() <= T + 1e-6).all())
    assert bool(((z[free] >= 0) & (z[free] <= 0.8 - T + 1e-6)).all())
    assert torch.allclose(target, projective_tsdf(z, torch.full_like(z, 0.8), T), atol=1e-5)
    columns = points[:, 0] / z * CAMERA.fx + CAMERA.cx  # never the invalid left columns
    assert bool((columns[z > 0.01] >= 9.5).all())


def test_the_warm_start_fits_the_tsdf_and_leaves_colour_alone() -> None:
    _, field, view = _setup()
    colour = [p.detach().clone() for p in field.appearance_decoder.parameters()]
    colour_planes = [level.planes.detach().clone() for level in field.appearance.levels.values()]
    generator = torch.Generator().manual_seed(0)
    points, target = warm_start_points(view, torch.eye(4), 2000, T, 0.25, generator)

    def error() -> float:
        with torch.no_grad():
            return float((field.query(points, with_rgb=False).sdf - target).square().mean())

    before = error()
    plan = WarmStart(steps=25, points=1000)
    tsdf_warm_start(field, view, torch.eye(4), plan, 0.005, 0.001, generator)
    assert error() < 0.3 * before
    assert all(
        torch.equal(a, b)
        for a, b in zip(colour, field.appearance_decoder.parameters(), strict=True)
    )
    after = [level.planes for level in field.appearance.levels.values()]
    assert all(torch.equal(a, b) for a, b in zip(colour_planes, after, strict=True))


def test_the_first_schedule_carries_the_warm_start_only_when_asked() -> None:
    mapping = ESLAMConfig().mapping
    assert mapping_schedule(mapping, first=True).warm_start is None  # paper: none
    tsdf = dataclasses.replace(
        mapping, first_warm_start="tsdf", first_warm_start_steps=7, first_warm_start_points=99
    )
    assert mapping_schedule(tsdf, first=True).warm_start == WarmStart(7, 99)
    assert mapping_schedule(tsdf, first=False).warm_start is None


def test_map_window_runs_the_warm_start_first() -> None:
    """With zero rendering steps the call is the warm start alone: same field as calling
    tsdf_warm_start directly with the same generator."""
    config, field, view = _setup()
    _, twin, _ = _setup()
    plan = WarmStart(steps=3, points=256)
    schedule = dataclasses.replace(
        mapping_schedule(config.mapping, first=True), iterations=0, warm_start=plan
    )
    settings = MappingSettings(config.mapping, config.render, config.loss)
    map_window(
        field,
        [view],
        torch.eye(4)[None],
        [False],
        settings,
        schedule,
        torch.Generator().manual_seed(0),
    )
    tsdf_warm_start(
        twin,
        view,
        torch.eye(4),
        plan,
        config.mapping.lr_planes,
        config.mapping.lr_decoders,
        torch.Generator().manual_seed(0),
    )
    for a, b in zip(field.state_dict().values(), twin.state_dict().values(), strict=True):
        assert torch.equal(a, b)


def _turned_view_pose() -> torch.Tensor:
    """A camera at z = 0.5 turned half round about y: it looks down -z, its wall (depth
    0.8) at z = -0.3, where the identity camera's view never reaches."""
    pose = torch.eye(4)
    pose[0, 0] = pose[2, 2] = -1.0
    pose[2, 3] = 0.5
    return pose


def test_the_warm_start_on_several_views_fits_each_of_them() -> None:
    """The map rebuilt after a loop correction (``mapping.loops.map: rebuild``): steps
    taken in turn over the views fit every view's TSDF; the same steps on the first view
    alone leave the second's unfitted (so the test sees which views were used)."""
    _, field, view = _setup()
    _, alone, _ = _setup()
    poses = torch.stack([torch.eye(4), _turned_view_pose()])
    draws = torch.Generator().manual_seed(0)
    targets = [warm_start_points(view, pose, 2000, T, 1.0, draws) for pose in poses]  # bands

    def errors(of: SceneField) -> list[float]:
        with torch.no_grad():
            return [
                float((of.query(points, with_rgb=False).sdf - target).square().mean())
                for points, target in targets
            ]

    before = errors(field)
    plan = WarmStart(steps=60, points=1000)
    tsdf_warm_start_views(field, [view, view], poses, plan, 0.005, 0.001, draws)
    tsdf_warm_start(alone, view, poses[0], plan, 0.005, 0.001, draws)
    both, first_only = errors(field), errors(alone)
    assert both[0] < 0.3 * before[0] and both[1] < 0.3 * before[1]
    assert first_only[1] > 0.5 * before[1]
    # a mapping call's warm start (a later call's in real time: mapping.realtime_warm_start)
    # takes its whole window the same way
    config, window, _ = _setup()
    settings = MappingSettings(config.mapping, config.render, config.loss)
    schedule = MappingSchedule(0, 1.0, 10, warm_start=plan)
    warm_start_window(window, [view, view], poses, settings, schedule, draws)
    called = errors(window)
    assert called[0] < 0.3 * before[0] and called[1] < 0.3 * before[1]


def test_the_warm_start_needs_a_pose_per_view() -> None:
    _, field, view = _setup()
    with pytest.raises(ValueError, match="2 views with 1 poses"):
        tsdf_warm_start_views(
            field, [view, view], torch.eye(4)[None], WarmStart(1, 10), 0.005, 0.001,
            torch.Generator().manual_seed(0),
        )  # fmt: skip
