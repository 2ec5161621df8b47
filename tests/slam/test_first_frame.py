"""The fast first frame: the shipped short first mapping call predicts held-out frames
about as well as the paper's 1000 iterations.

A fresh field is fitted to frame 0 of a synthetic room with its ground-truth pose, as
the run loop's first mapping call does, once with the paper's schedule (1000 steps at
5x the learning rates) and once with the first-frame schedule the CPU preset ships;
both are scored on held-out frames (:func:`eslam.render.held_out.held_out_errors`,
pixels frame 0 observed). A map fitted for only a few steps must fail the same bound,
so the comparison can fail.
"""

from __future__ import annotations

import dataclasses

import pytest
import torch

from eslam.config import ESLAMConfig, load_config
from eslam.render.held_out import HeldOutErrors, held_out_errors
from eslam.render.rays import camera_directions
from eslam.slam.mapping import MappingSchedule, MappingSettings, map_window, mapping_schedule
from eslam.slam.state import new_field
from eslam.slam.views import make_view
from eslam.synthetic import SynthConfig, build_scene, generate_sequence, scene_bound
from eslam.workflows.demo import DEMO_CONFIG

pytestmark = pytest.mark.slow  # 1000 mapping steps (still run in CI)

SCENE = SynthConfig(frames=7, width=80, height=60, seed=0)
HELD_OUT = (3, 6)
REDUCED = [
    "mapping.rays=200",
    "render.samples_stratified=8",
    "render.samples_surface=4",
]
"""A workload small enough for CI; the schedules are what is compared."""
PAPER = MappingSchedule(iterations=1000, lr_factor=5.0, rays=200)


def fit(config: ESLAMConfig, schedule: MappingSchedule) -> HeldOutErrors:
    frames = list(generate_sequence(SCENE))
    first = frames[0]
    view = make_view(
        torch.from_numpy(first.rgb).float() / 255.0,
        torch.from_numpy(first.depth),
        camera_directions(first.intrinsics),
    )
    bound = torch.tensor(scene_bound(build_scene(SCENE.scene, SCENE.seed)))
    field = new_field(config, bound, torch.device("cpu"))
    settings = MappingSettings(config.mapping, config.render, config.loss)
    pose = torch.from_numpy(first.pose_gt).float()[None]
    map_window(field, [view], pose, [False], settings, schedule, torch.Generator().manual_seed(0))
    field.requires_grad_(False)
    return held_out_errors(field, [frames[i] for i in HELD_OUT], observed_by=first)


def test_fast_first_frame_is_within_10_percent_of_1000_iterations() -> None:
    config = load_config(DEMO_CONFIG, REDUCED)  # the demo = the CPU preset
    shipped = mapping_schedule(config.mapping, first=True)
    assert shipped.iterations <= 200, "the fast first frame is a fraction of 1000 steps"
    fast = dataclasses.replace(shipped, rays=PAPER.rays * (shipped.rays // config.mapping.rays))
    paper = fit(config, PAPER)
    quick = fit(config, fast)
    too_short = fit(config, dataclasses.replace(fast, iterations=10))
    assert paper.missed < 0.01 and quick.missed < 0.01
    assert quick.depth_l1_m <= 1.10 * paper.depth_l1_m, (quick, paper)
    assert too_short.depth_l1_m > 1.10 * paper.depth_l1_m, (too_short, paper)
