"""The run loop end to end on a tiny synthetic scene: outputs, accuracy, and resume."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import ESLAMConfig, load_config
from eslam.io.trajectory import read_tum_trajectory
from eslam.slam.session import run_slam
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY_FRAMES, tiny_config

pytestmark = pytest.mark.slow  # integration: whole runs (still run in CI)

FRAMES = TINY_FRAMES


@pytest.fixture(scope="module")
def sequence(tiny_sequence: Path) -> Path:
    return tiny_sequence


def _config(sequence: Path, *extra: str) -> ESLAMConfig:
    return tiny_config(sequence, *extra)


@pytest.fixture(scope="module")
def full_run(tiny_run):
    return tiny_run


def test_run_writes_every_output(full_run) -> None:
    root = full_run.run_dir
    for name in (
        "config.yaml",
        "trajectory.txt",
        "trajectory_gt.txt",
        "map.pt",
        "mesh.ply",
        "metrics.json",
        "timings.json",
        "log.txt",
    ):
        assert (root / name).is_file(), name
    metrics = json.loads((root / "metrics.json").read_text())
    assert metrics["frames"] == FRAMES and metrics["device"] == "cpu"
    assert {"ate_rmse_cm", "ate_mean_cm", "fpt_s", "peak_memory_mb"} <= set(metrics)
    timings = json.loads((root / "timings.json").read_text())
    assert len(timings["tracking_s"]) == len(timings["mapping_s"]) == FRAMES
    timestamps, poses = read_tum_trajectory(root / "trajectory.txt")
    assert len(timestamps) == FRAMES
    np.testing.assert_allclose(poses, full_run.poses, atol=1e-6)
    saved = load_config(root / "config.yaml")
    assert saved.tracking.render.rays == 200 and saved.scene.bound is not None


def test_run_tracks_the_synthetic_camera(full_run, tiny_static_ate_cm: float) -> None:
    # 12 frames of 80x60 with a few hundred rays: a coarse but real check that tracking
    # and mapping work together (the demo, at 160x120 and 60 frames, reaches ~0.3 cm).
    # A tracker that never moves scores tiny_static_ate_cm (~2.5 cm): be far better.
    assert full_run.metrics["ate_rmse_cm"] < 0.3 * tiny_static_ate_cm
    first_gt = read_tum_trajectory(full_run.run_dir / "trajectory_gt.txt")[1][0]
    np.testing.assert_allclose(full_run.poses[0], first_gt, atol=1e-6)


def test_resume_gives_the_same_trajectory(sequence: Path, full_run, tmp_path: Path) -> None:
    out = tmp_path / "interrupted"
    config = _config(sequence)
    partial = run_slam(config, out, stop_after=7)
    assert partial.metrics["frames"] == 7
    assert not (out / "mesh.ply").exists(), "an unfinished run writes no mesh"
    _add_metrics(out, accuracy_cm=1.0)  # `eslam eval` of the interrupted run
    resumed = run_slam(load_config(out / "config.yaml"), out, resume=True)
    assert resumed.metrics["frames"] == FRAMES
    np.testing.assert_allclose(resumed.poses, full_run.poses, rtol=0, atol=1e-7)
    assert "resuming" in (out / "log.txt").read_text()
    # frames were added: a score of the 7-frame map no longer describes the run
    assert "accuracy_cm" not in json.loads((out / "metrics.json").read_text())


def _add_metrics(run_dir: Path, **keys: float) -> dict:
    path = run_dir / "metrics.json"
    metrics = {**json.loads(path.read_text()), **keys}
    path.write_text(json.dumps(metrics))
    return metrics


def test_resuming_a_finished_run_keeps_the_keys_eslam_eval_added(full_run, tmp_path: Path) -> None:
    """Resuming a finished run rewrote metrics.json with the run's keys only."""
    out = tmp_path / "finished"
    shutil.copytree(full_run.run_dir, out)
    before = _add_metrics(out, accuracy_cm=1.5, depth_l1_cm=2.5, peak_memory_mb=1e6)
    resumed = run_slam(load_config(out / "config.yaml"), out, resume=True)
    after = json.loads((out / "metrics.json").read_text())
    assert after == resumed.metrics
    assert after["accuracy_cm"] == 1.5 and after["depth_l1_cm"] == 2.5
    assert after["frames"] == before["frames"] == FRAMES
    assert after["peak_memory_mb"] == 1e6  # the peak over every process of the run


def test_cli_run_refuses_an_existing_run_and_missing_data(
    sequence: Path, full_run, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code = main(["run", str(DEMO_CONFIG), "--out", str(full_run.run_dir), f"--data={sequence}"])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "already holds a run" in err and "\n" not in err
    # an override after the options is taken as an override, not an unknown argument
    code = main(["run", str(DEMO_CONFIG), "--out", str(tmp_path / "new"), "seed=1"])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "data.path is not set (pass --data PATH" in err and "\n" not in err


def test_cli_resume_of_a_folder_that_is_not_a_run(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["resume", str(tmp_path)]) == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "config.yaml: not found: not a run folder" in err and "`eslam run" in err
    assert main(["resume", str(tmp_path / "nowhere")]) == EXIT_USER_ERROR
    assert "run folder not found" in capsys.readouterr().err
