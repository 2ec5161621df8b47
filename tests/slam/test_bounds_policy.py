"""Runs without a bound, with a bound too small (growth), and with growth off (warning)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import DataConfig, ESLAMConfig, load_config
from eslam.data import open_sequence
from eslam.errors import InputError
from eslam.geometry.bounds import depth_points, fraction_outside
from eslam.io.checkpoint import load_checkpoint
from eslam.slam.mapping.bounds_policy import bound_from_frame, check_depth_found, check_some_depth
from eslam.slam.session import run_slam
from eslam.synthetic import read_synthetic_bound
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY as LOOP_TINY

pytestmark = pytest.mark.slow  # integration: whole runs (still run in CI)

FRAMES = 12
# tests/slam/test_loop.py's tiny settings, without the mesh (bounds are what is tested)
TINY = [*LOOP_TINY, "output.mesh=false"]
TOO_SMALL = "scene.bound=[[0.5, 1.0], [0.5, 1.0], [0.5, 1.0]]"
"""A hand-set bound that misses every point of the synthetic room's first frames."""


@pytest.fixture(scope="module")
def sequence(tiny_sequence: Path) -> Path:
    return tiny_sequence


def _config(sequence: Path, *extra: str) -> ESLAMConfig:
    return load_config(DEMO_CONFIG, [f"data.path={sequence}", *TINY, *extra])


def _saved_bound(run_dir: Path) -> torch.Tensor:
    return load_checkpoint(run_dir / "map.pt")["field"]["bound"]


def _observed_points(sequence: Path) -> torch.Tensor:
    """Every frame's depth points, placed with the ground-truth poses."""
    frames = open_sequence(DataConfig(path=str(sequence)))
    gt = frames.gt_poses()
    return torch.cat(
        [
            depth_points(
                torch.from_numpy(frames[i].depth).double(),
                frames.intrinsics,
                torch.from_numpy(gt[i]),
            )
            for i in range(len(frames))
        ]
    )


@pytest.fixture(scope="module")
def given_run(sequence: Path, tmp_path_factory: pytest.TempPathFactory):
    bound = read_synthetic_bound(sequence)
    return run_slam(_config(sequence, f"scene.bound={bound}"), tmp_path_factory.mktemp("g") / "r")


@pytest.fixture(scope="module")
def small_run(sequence: Path, tmp_path_factory: pytest.TempPathFactory):
    return run_slam(_config(sequence, TOO_SMALL), tmp_path_factory.mktemp("s") / "run")


def test_automatic_bound_covers_the_scene_and_tracks(
    sequence: Path, given_run, tmp_path: Path, tiny_static_ate_cm: float
) -> None:
    auto = run_slam(_config(sequence), tmp_path / "auto")
    log = (tmp_path / "auto" / "log.txt").read_text()
    assert "scene bound estimated from the first frame with depth" in log
    bound = _saved_bound(auto.run_dir)
    assert fraction_outside(_observed_points(sequence), bound) < 0.01
    assert auto.metrics["ate_rmse_cm"] < 0.3 * tiny_static_ate_cm  # a dead tracker: 1.0x
    assert auto.metrics["ate_rmse_cm"] < 2.0 * given_run.metrics["ate_rmse_cm"] + 0.5
    assert load_config(auto.run_dir / "config.yaml").scene.bound is None


def test_too_small_bound_grows_and_still_tracks(
    sequence: Path, given_run, small_run, tiny_static_ate_cm: float
) -> None:
    log = (small_run.run_dir / "log.txt").read_text()
    assert "scene bound grown (100.0% of a keyframe's depth points were outside)" in log
    bound = _saved_bound(small_run.run_dir)
    assert bool((bound[:, 0] <= 0.5).all()) and bool((bound[:, 1] >= 1.0).all())
    assert fraction_outside(_observed_points(sequence), bound) < 0.01
    # a dead tracker scores 1.0x; the reference sampling gives 0.32x here (0.80 cm), the
    # batched grid_sample 0.29x: the same maths, summed in another order
    assert small_run.metrics["ate_rmse_cm"] < 0.4 * tiny_static_ate_cm
    assert small_run.metrics["ate_rmse_cm"] < 2.0 * given_run.metrics["ate_rmse_cm"] + 0.5


def test_resume_after_growth_gives_the_same_trajectory(
    sequence: Path, small_run, tmp_path: Path
) -> None:
    out = tmp_path / "interrupted"
    run_slam(_config(sequence, TOO_SMALL), out, stop_after=7)
    assert "scene bound grown" in (out / "log.txt").read_text()
    assert not torch.equal(_saved_bound(out), torch.tensor([[0.5, 1.0]] * 3))
    resumed = run_slam(load_config(out / "config.yaml"), out, resume=True)
    np.testing.assert_allclose(resumed.poses, small_run.poses, rtol=0, atol=1e-7)


def test_growth_off_warns_once_with_the_share_of_points_lost(
    sequence: Path, tmp_path: Path
) -> None:
    result = run_slam(
        _config(sequence, TOO_SMALL, "scene.grow=false"), tmp_path / "r", stop_after=7
    )
    log = (tmp_path / "r" / "log.txt").read_text()
    assert log.count("WARNING") == 1, log
    assert "100.0% of a keyframe's depth points lie outside the scene bound" in log
    assert "scene.grow is off" in log and "grown" not in log
    assert np.isfinite(result.poses).all()
    fitted = torch.tensor([[0.5, 1.22]] * 3)  # [0.5, 1.0] fitted to multiples of 0.24 m
    torch.testing.assert_close(_saved_bound(result.run_dir), fitted, rtol=0, atol=1e-6)


def test_growth_beyond_max_extent_is_refused_with_a_warning(sequence: Path, tmp_path: Path) -> None:
    config = _config(sequence, TOO_SMALL, "scene.max_extent=1.0")
    run_slam(config, tmp_path / "r", stop_after=1)
    log = (tmp_path / "r" / "log.txt").read_text()
    assert "would pass scene.max_extent=1.0 m" in log and "grown" not in log


def test_bound_from_the_first_frame_with_depth(sequence: Path, tmp_path: Path) -> None:
    frames = open_sequence(DataConfig(path=str(sequence)))
    config = _config(sequence)
    with pytest.raises(InputError, match=r"first 30 frames has valid depth.*scene.bound"):
        check_depth_found(30, str(sequence))
    check_depth_found(29, str(sequence))
    pose = torch.from_numpy(frames.gt_poses()[0]).float()
    estimated = bound_from_frame(config.scene, frames[0], pose)
    first = depth_points(
        torch.from_numpy(frames[0].depth).double(),
        frames.intrinsics,
        torch.from_numpy(frames.gt_poses()[0]),
    )
    assert fraction_outside(first, estimated) < 0.01
    centre = torch.from_numpy(frames.gt_poses()[0][:3, 3]).float()
    assert bool((estimated[:, 0] < centre - 0.49).all() and (estimated[:, 1] > centre).all())


def test_the_last_frame_refuses_a_run_without_any_depth() -> None:
    with pytest.raises(InputError, match=r"data: none of its 12 frames has valid depth"):
        check_some_depth(11, 12, 0, "data")
    check_some_depth(10, 12, 0, "data")  # a later frame may still have depth
    check_some_depth(11, 12, 1, "data")  # a frame was mapped
    check_some_depth(11, None, 0, "data")  # a stream of unknown length


@pytest.mark.parametrize("bound_given", [True, False])
def test_a_sequence_without_any_depth_is_one_line_and_saves_nothing(
    sequence: Path, tmp_path: Path, bound_given: bool, capsys: pytest.CaptureFixture[str]
) -> None:
    # issue 15's failure drills: all-zero depth finished with exit 0, an empty map and
    # metrics of predicted poses; its depthless frames were checkpointed, so a resume
    # after fixing the depth would have skipped them
    zero = tmp_path / "zero"
    shutil.copytree(sequence, zero)
    for path in (zero / "results").glob("depth*.png"):
        Image.fromarray(np.zeros_like(np.asarray(Image.open(path)))).save(path)
    run = tmp_path / "run"
    bound = [f"scene.bound={read_synthetic_bound(sequence)}"] if bound_given else []
    args = ["run", str(DEMO_CONFIG), "--data", str(zero), "--out", str(run), *TINY, *bound]
    assert main([*args, "output.checkpoint_every=2"]) == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert f"none of its {FRAMES} frames has valid depth" in err
    assert "before its first frame was complete" in err and f"eslam resume {run}" in err
    assert "\n" not in err and "Traceback" not in err
    assert not (run / "map.pt").exists() and not (run / "trajectory.txt").exists()
