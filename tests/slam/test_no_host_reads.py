"""No optimisation step reads the device on the host (tests/tripwire.py), on CPU in CI:
the rendering tracker's step and the mapping step (the CUDA sync test checks them on
a GPU: test_steps.py)."""

from __future__ import annotations

import pytest
import torch

from eslam.config import ESLAMConfig
from eslam.field.scene_field import SceneField
from eslam.render.rays import camera_directions
from eslam.slam.mapping import MappingSettings, WindowPoses, mapping_optimiser, mapping_step
from eslam.slam.tracking import (
    PoseVariables,
    TrackingSettings,
    frozen,
    pose_optimiser,
    tracking_step,
)
from eslam.slam.views import make_view
from eslam.types import Intrinsics
from tests.tripwire import HostRead, no_host_reads

CAMERA = Intrinsics(width=40, height=30, fx=30.0, fy=30.0, cx=19.5, cy=14.5)
BOUND = torch.tensor([[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.5]])


def _setup():
    config = ESLAMConfig()
    field = SceneField(config.field, BOUND, torch.Generator().manual_seed(0))
    depth = torch.full((30, 40), 0.8)
    depth[:, :10] = 0.0
    rgb = torch.rand(30, 40, 3, generator=torch.Generator().manual_seed(1))
    view = make_view(rgb, depth, camera_directions(CAMERA), border=2)
    return config, field, view


def test_the_tripwire_catches_a_host_read_in_eslam_code() -> None:
    _, _, view = _setup()
    with no_host_reads(), pytest.raises(HostRead, match=r"__int__ .*views\.py"):
        view.sampleable_pixels()  # int(count): a read the loop makes between frames
    assert view.sampleable_pixels() > 0  # restored on the way out


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
