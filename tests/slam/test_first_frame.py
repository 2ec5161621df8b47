"""The fast first frame: a short first mapping call loses nothing.

The CPU preset (and the demo) map the first frame with a TSDF warm start (a regression
onto the first depth image's projective TSDF, no rendering) and 30 rendering steps
instead of the paper's 1000, so the first pose is tracked minutes sooner; its map is as
good as the 1000-step one on held-out frames (benchmarks/first_frame.py,
docs/benchmarks.md "Time to the first pose"). Without the warm start a short first map
is rougher (3.3x the held-out depth L1 at 60 steps), but the following mapping calls
refine it: a run with a 60-step first frame tracks as well as one with a long first
frame (500 steps here, to keep CI short; full runs: docs/results.md "Replica room0,
frames 0-19"). Maps fitted too briefly must fail the held-out comparisons, so those
comparisons can fail.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from eslam.config import ESLAMConfig, load_config
from eslam.render.held_out import HeldOutErrors, held_out_errors
from eslam.render.rays import camera_directions
from eslam.slam.mapping.mapper import MappingSchedule, MappingSettings, map_window, mapping_schedule
from eslam.slam.mapping.warm_start import WarmStart
from eslam.slam.session import run_slam
from eslam.slam.state import new_field
from eslam.slam.views import make_view
from eslam.synthetic import SynthConfig, build_scene, generate_sequence, scene_bound
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import tiny_config

pytestmark = pytest.mark.slow  # 1000 first-frame mapping steps (still run in CI)

PAPER_FIRST_ITERATIONS = 1000
LONG_FIRST_ITERATIONS = 500
"""The long run of the comparison (half the paper's, to keep CI short)."""


def test_the_cpu_preset_maps_the_first_frame_briefly() -> None:
    shipped = mapping_schedule(load_config(DEMO_CONFIG).mapping, first=True)
    paper = mapping_schedule(ESLAMConfig().mapping, first=True)
    assert paper.iterations == PAPER_FIRST_ITERATIONS  # the paper's stays the default
    assert paper.warm_start is None
    assert shipped.iterations <= 0.1 * paper.iterations
    assert shipped.warm_start is not None


def test_a_short_first_frame_tracks_as_well_as_a_long_one(
    tiny_sequence: Path, tiny_run, tiny_static_ate_cm: float, tmp_path: Path
) -> None:
    """On these coarse tiny settings the ATE moves by a few millimetres with any change
    of schedule and with the machine (Xeon VM: 60 steps 0.50 cm, 500 steps 0.28 cm,
    1000 over 0.41 cm; EPYC VM: 0.49 and 0.17 cm), so the bound is loose: both far
    below a tracker that never moves, and the short one within 3x."""
    short = tiny_run.metrics["ate_rmse_cm"]  # the tiny settings map frame 0 with 60 steps
    assert tiny_config(tiny_sequence).mapping.first_iterations <= 100
    long = run_slam(
        tiny_config(tiny_sequence, f"mapping.first_iterations={LONG_FIRST_ITERATIONS}"),
        tmp_path / "run",
    ).metrics["ate_rmse_cm"]
    assert long < 0.3 * tiny_static_ate_cm and short < 0.3 * tiny_static_ate_cm
    assert short <= 3.0 * long + 0.05, f"{short:.3f} cm with 60 steps, {long:.3f} cm with 500"


SCENE = SynthConfig(frames=7, width=80, height=60, seed=0)


def first_map_errors(
    iterations: int, lr_factor: float = 5.0, warm_start: WarmStart | None = None
) -> HeldOutErrors:
    """Held-out errors of frames 3 and 6 after fitting frame 0 (the demo's settings,
    200 rays of 8 + 4 samples) for ``iterations`` steps at ``lr_factor`` times the
    learning rates, after ``warm_start`` (None: none)."""
    config = load_config(
        DEMO_CONFIG, ["mapping.rays=200", "render.samples_stratified=8", "render.samples_surface=4"]
    )
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
    schedule = MappingSchedule(iterations, lr_factor, config.mapping.rays, warm_start=warm_start)
    map_window(field, [view], pose, [False], settings, schedule, torch.Generator().manual_seed(0))
    field.requires_grad_(False)
    return held_out_errors(field, [frames[3], frames[6]], observed_by=first)


def test_held_out_errors_tell_a_fitted_first_map_from_a_barely_started_one() -> None:
    fitted, barely = first_map_errors(60), first_map_errors(10)
    assert fitted.missed < 0.05
    assert barely.depth_l1_m > 2.0 * fitted.depth_l1_m
    assert barely.surface_sdf_m > 2.0 * fitted.surface_sdf_m


PAPER_FIRST_MAP_DEPTH_L1_M = 0.00282
"""Held-out depth L1 of ``first_map_errors(1000)``, the paper's 1000 steps at 5x (0.282
cm; 68 s of CPU, too long for CI, so kept here; recompute it with
``python -c "from tests.slam.test_first_frame import first_map_errors as f;
print(f(1000).depth_l1_m)"``; 1 thread, torch 2.13 CPU)."""


def test_the_fast_first_frame_is_within_10_percent_of_the_1000_iteration_one() -> None:
    """The CPU preset's first frame (TSDF warm start, 30 rendering steps at 2x) against
    the paper's 1000 steps: held-out depth L1 at most 1.10x (0.201 cm measured, 0.71x).
    The same 30 steps without the warm start are far off (6.9 cm), so the bound can fail."""
    preset = mapping_schedule(load_config(DEMO_CONFIG).mapping, first=True)
    fast = first_map_errors(preset.iterations, preset.lr_factor, preset.warm_start)
    assert fast.missed < 0.05
    assert fast.depth_l1_m <= 1.10 * PAPER_FIRST_MAP_DEPTH_L1_M, f"{fast.depth_l1_m:.5f} m"
    plain = first_map_errors(preset.iterations, preset.lr_factor)
    assert plain.depth_l1_m > 1.10 * PAPER_FIRST_MAP_DEPTH_L1_M
