"""No optimisation step reads the device on the host (tests/tripwire.py), on CPU in CI:
the rendering tracker's step, the SDF tracker's Levenberg-Marquardt step and the
mapping step (the CUDA sync test checks the first and last on a GPU: test_steps.py)."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from eslam.config import SdfTrackerConfig
from eslam.render.rays import camera_directions
from eslam.slam.mapping.mapper import MappingSettings, WindowPoses, mapping_optimiser, mapping_step
from eslam.slam.tracking.render import (
    PoseVariables,
    TrackingSettings,
    frozen,
    pose_optimiser,
    tracking_step,
)
from eslam.slam.tracking.sdf import Solver, lm_step, sdf_points, track_sdf
from eslam.slam.tracking.sdf_system import linearise
from eslam.slam.views import make_view
from tests.slam.test_sdf_tracking import CAMERA as SDF_CAMERA
from tests.slam.test_sdf_tracking import TRUE_POSE, AnalyticField, perturbed, render_depth
from tests.slam.test_steps import _setup  # the step tests' field and 40x30 view
from tests.tripwire import HostRead, no_host_reads


def test_the_tripwire_catches_a_host_read_in_eslam_code() -> None:
    _, _, view = _setup()
    with no_host_reads(), pytest.raises(HostRead, match=r"__int__ .*views\.py"):
        view.sampleable_pixels()  # int(count): a read the loop makes between frames
    assert view.sampleable_pixels() > 0  # restored on the way out
    with no_host_reads(count_only=True) as seen:  # reads from here are listed, not raised
        view.depth[view.depth > 0]  # a boolean mask: its shape waits for the values
        view.depth[:5], view.depth[torch.arange(3)]  # plain and integer indexing: no read
    assert [read.split()[0] for read in seen] == ["__getitem__"]


def test_the_render_tracking_step_reads_nothing_on_the_host() -> None:
    config, field, view = _setup()
    generator = torch.Generator().manual_seed(0)
    settings = TrackingSettings(config.tracking.render, config.render, config.loss)
    variables = PoseVariables.from_pose(torch.eye(4))
    optimiser = pose_optimiser(variables, config.tracking.render)
    with frozen(field):
        tracking_step(field, view, variables, optimiser, settings, generator)  # lazy init
        before = variables.translation.detach().clone()
        with no_host_reads():
            tracking_step(field, view, variables, optimiser, settings, generator)
    assert not torch.equal(before, variables.translation.detach())  # it did step


def test_the_mapping_step_reads_nothing_on_the_host() -> None:
    config, field, view = _setup()
    generator = torch.Generator().manual_seed(0)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    window = WindowPoses.create(torch.eye(4).repeat(2, 1, 1), [False, True])
    optimiser = mapping_optimiser(field, window, config.mapping, 1.0)
    mapping_step(field, [view, view], window, optimiser, mapping, generator)  # lazy init
    before = [p.detach().clone() for p in field.parameters()]
    with no_host_reads():
        mapping_step(field, [view, view], window, optimiser, mapping, generator)
    assert any(
        not torch.equal(a, b.detach()) for a, b in zip(before, field.parameters(), strict=True)
    )


def _analytic_view():
    """The SDF tracker tests' view of their analytic room, at its true pose."""
    depth = render_depth(TRUE_POSE)
    rgb = torch.full((SDF_CAMERA.height, SDF_CAMERA.width, 3), 0.5)
    return make_view(rgb, depth, camera_directions(SDF_CAMERA), border=2)


@pytest.mark.parametrize("colour", [0.0, 0.05])
def test_the_sdf_tracking_step_reads_nothing_on_the_host(colour: float) -> None:
    view = _analytic_view()
    config = dataclasses.replace(SdfTrackerConfig(), degeneracy=0.01, colour_weight=colour)
    field = AnalyticField()
    points, pixels = sdf_points(view, 500, torch.Generator().manual_seed(0))
    colours = view.rgb[pixels] if colour > 0 else None
    start = perturbed(0.03, 3.0, seed=0)
    system = linearise(field, points, start, config, colours)
    solver = Solver(
        start,
        system,
        torch.tensor(config.damping, dtype=torch.float64),
        torch.ones((), dtype=torch.bool),
        torch.zeros((), dtype=torch.int64),
    )
    with no_host_reads():
        for _ in range(3):
            solver = lm_step(field, points, colours, config, solver)
    assert not torch.equal(solver.pose, start) and int(solver.iterations) == 3


def test_sdf_tracking_reads_the_host_a_fixed_number_of_times_per_frame() -> None:
    """Without polling (as on a GPU) the reads are per frame (quality, information),
    not per iteration; polling (a CPU's default) stops early with the same pose."""
    view = _analytic_view()
    start = perturbed(0.03, 3.0, seed=1)
    reads = {}
    poses = {}
    for iterations in (4, 12):
        config = dataclasses.replace(SdfTrackerConfig(), iterations=iterations, degeneracy=0.01)
        with no_host_reads(count_only=True) as seen:
            result = track_sdf(
                AnalyticField(), view, start, config, torch.Generator().manual_seed(0), poll=False
            )
        reads[iterations] = [read for read in seen if read.endswith("(eslam)")]
        polled = track_sdf(
            AnalyticField(), view, start, config, torch.Generator().manual_seed(0), poll=True
        )
        assert torch.equal(polled.pose, result.pose)
        assert polled.quality == result.quality
        poses[iterations] = result.pose
    assert len(reads[4]) == len(reads[12]) > 0
    assert not torch.equal(poses[12], start)


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
@pytest.mark.parametrize("degeneracy", [0.0, 0.01])
def test_the_sdf_tracking_step_does_not_sync_with_the_device(degeneracy: float) -> None:
    """On a GPU, as CUDA's sync debug mode sees it (the degeneracy test's eigh included),
    on the step tests' field and view (test_steps.py)."""
    config, field, view = _setup("cuda")
    settings = dataclasses.replace(config.tracking.sdf, degeneracy=degeneracy)
    points, _ = sdf_points(view, 500, torch.Generator(device="cuda").manual_seed(0))
    start = torch.eye(4, device="cuda")
    with frozen(field):
        solver = Solver(
            start,
            linearise(field, points, start, settings),
            torch.tensor(settings.damping, dtype=torch.float64, device="cuda"),
            torch.ones((), dtype=torch.bool, device="cuda"),
            torch.zeros((), dtype=torch.int64, device="cuda"),
        )
        solver = lm_step(field, points, None, settings, solver)  # may set up lazily
        torch.cuda.synchronize()
        torch.cuda.set_sync_debug_mode("error")
        try:
            for _ in range(3):
                solver = lm_step(field, points, None, settings, solver)
        finally:
            torch.cuda.set_sync_debug_mode("default")
