"""The run loop with imperfect input: frame selection, empty depth, bad input before writing."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import load_config
from eslam.data.replica import write_replica_sequence
from eslam.io.trajectory import read_tum_trajectory
from eslam.slam.session import run_slam
from eslam.synthetic import (
    SynthConfig,
    build_scene,
    generate_sequence,
    read_synthetic_bound,
    scene_bound,
    write_synthetic_sequence,
)
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY, static_ate_cm

SCENE = SynthConfig(frames=9, width=80, height=60, seed=3)


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("input") / "data"
    write_synthetic_sequence(root, SCENE)
    return root


def _args(sequence: Path, out: Path) -> list[str]:
    bound = read_synthetic_bound(sequence)
    return ["run", str(DEMO_CONFIG), "--data", str(sequence), "--out", str(out),
            f"scene.bound={bound}", *TINY]  # fmt: skip


def test_start_stride_max_frames_from_the_command_line(sequence: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    code = main([*_args(sequence, out), "--start", "1", "--stride", "2", "--max-frames", "3"])
    assert code == 0
    timestamps, poses = read_tum_trajectory(out / "trajectory.txt")
    np.testing.assert_array_equal(timestamps, [1.0, 3.0, 5.0])  # the dataset's frame numbers
    gt_times, gt = read_tum_trajectory(out / "trajectory_gt.txt")
    np.testing.assert_array_equal(gt_times, [1.0, 3.0, 5.0])
    np.testing.assert_allclose(poses[0], gt[0], atol=1e-6)  # frame 1 starts the run at its GT
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["frames"] == 3
    assert load_config(out / "config.yaml").data.stride == 2


def test_frames_without_depth_are_skipped_with_a_warning(tmp_path: Path) -> None:
    frames = list(generate_sequence(SCENE))
    for k in (0, 4):  # the first frame (mapping waits for frame 1) and a mapped frame
        frames[k] = dataclasses.replace(frames[k], depth=np.zeros_like(frames[k].depth))
    data = tmp_path / "data"
    write_replica_sequence(data, frames)
    bound = _scene_bound(SCENE)
    config = load_config(DEMO_CONFIG, [f"data.path={data}", f"scene.bound={bound}", *TINY])
    result = run_slam(config, tmp_path / "run")
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "frame 0 (timestamp 0.000000) has no valid depth: skipped" in log
    assert "frame 4 (timestamp 4.000000) has no valid depth: skipped" in log
    assert "mapped frame 1: window [1]" in log  # the first map moved to the first frame with depth
    assert np.isfinite(result.poses).all()
    # a tracker that never moves scores static_ate_cm; frames 0 and 4 keep predicted poses
    # (under 0.3 of it on an AMD CPU, 0.31 on an AVX-512 Intel one: rounding differs)
    assert result.metrics["ate_rmse_cm"] < 0.5 * static_ate_cm([f.pose_gt for f in frames])


def _scene_bound(scene: SynthConfig) -> str:
    """The bound ``eslam synth`` records for ``scene`` (write_replica_sequence records none)."""
    return str([list(pair) for pair in scene_bound(build_scene(scene.scene, scene.seed))])


def test_bad_input_leaves_an_earlier_run_untouched(
    sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    assert main([*_args(sequence, out), "--max-frames", "2"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()

    # a wrong depth scale, asked for with --overwrite: refused before anything is written
    code = main([*_args(sequence, out), "--overwrite", "data.depth_scale=1"])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "depth000000.png: median depth" in err and "data.depth_scale" in err
    assert "\n" not in err
    # an unreadable last image: also refused up front
    broken = tmp_path / "broken"
    write_synthetic_sequence(broken, SynthConfig(frames=3, width=80, height=60, seed=3))
    (broken / "results" / "frame000002.jpg").write_bytes(b"not a jpeg")
    code = main([*_args(broken, out), "--overwrite"])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "frame000002.jpg: unreadable colour image" in err
    # an unknown config key
    code = main([*_args(sequence, out), "--overwrite", "tracking.render.iteration=3"])
    assert code == EXIT_USER_ERROR
    assert "tracking.render.iterations" in capsys.readouterr().err  # the closest valid key
    # a key that moved names its new place
    code = main([*_args(sequence, out), "--overwrite", "tracking.iterations=3"])
    assert code == EXIT_USER_ERROR
    assert "it moved: use 'tracking.render.iterations'" in capsys.readouterr().err
    # a device this machine does not have
    code = main([*_args(sequence, out), "--overwrite", "--device", "cuda:99"])
    assert code == EXIT_USER_ERROR
    assert "device 'cuda:99' asked for, but torch sees" in capsys.readouterr().err
    after = {p.name: p.read_bytes() for p in out.iterdir()}
    assert after == before


def test_a_bad_output_image_size_is_named(sequence: Path, tmp_path: Path, capsys) -> None:
    data = tmp_path / "data"
    write_synthetic_sequence(data, SynthConfig(frames=2, width=80, height=60, seed=3))
    Image.new("RGB", (40, 30)).save(data / "results" / "frame000001.jpg")
    assert main([*_args(data, tmp_path / "run")]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "frame000001.jpg: image is 40x30 but the intrinsics are for 80x60" in err
    assert not (tmp_path / "run").exists()
