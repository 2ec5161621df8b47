"""load_run: a run folder read back; a folder that is not a run is a one-line InputError."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from eslam.config import ESLAMConfig, config_to_dict, load_config, save_config
from eslam.errors import InputError
from eslam.io.run_dir import write_json
from eslam.io.saved_run import load_run
from eslam.io.trajectory import write_tum_trajectory


def _poses(count: int, offset: float) -> np.ndarray:
    poses = np.tile(np.eye(4), (count, 1, 1))
    poses[:, :3, 3] = np.arange(count)[:, None] * [0.1, 0.0, 0.0] + offset
    return poses


def _run(root: Path, ground_truth: bool = True) -> ESLAMConfig:
    """A run folder written by hand, the way `eslam run` writes one."""
    config = load_config(None, ["seed=7", "mapping.every=2", "data.path=somewhere"])
    save_config(config, root / "config.yaml")
    write_tum_trajectory(root / "trajectory.txt", np.arange(4.0), _poses(4, 0.0))
    if ground_truth:
        write_tum_trajectory(root / "trajectory_gt.txt", np.arange(4.0), _poses(4, 0.01))
        write_json(root / "metrics.json", {"ate_rmse_cm": 1.0, "frames": 4, "device": "cpu"})
    return config


def test_load_run_reads_config_trajectories_metrics_and_paths(tmp_path: Path) -> None:
    config = _run(tmp_path)
    (tmp_path / "map.pt").write_bytes(b"")
    run = load_run(tmp_path)
    assert run.root == tmp_path
    assert config_to_dict(run.config) == config_to_dict(config)
    assert run.config.seed == 7 and run.config.mapping.every == 2
    np.testing.assert_array_equal(run.timestamps, np.arange(4.0))
    np.testing.assert_allclose(run.poses, _poses(4, 0.0), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(run.gt_timestamps, np.arange(4.0))
    np.testing.assert_allclose(run.gt_poses, _poses(4, 0.01), rtol=0, atol=1e-12)
    assert run.metrics == {"ate_rmse_cm": 1.0, "frames": 4, "device": "cpu"}
    assert run.map_path == tmp_path / "map.pt"
    assert run.mesh_path is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.poses = run.gt_poses  # type: ignore[misc]


def test_run_without_ground_truth_metrics_or_map(tmp_path: Path) -> None:
    _run(tmp_path, ground_truth=False)
    (tmp_path / "mesh.ply").write_bytes(b"")
    run = load_run(str(tmp_path))
    assert run.gt_timestamps is None and run.gt_poses is None
    assert run.metrics == {}
    assert run.map_path is None and run.mesh_path == tmp_path / "mesh.ply"


def _one_line_error(path: Path, name: str, words: str) -> None:
    with pytest.raises(InputError, match=words) as caught:
        load_run(path)
    assert caught.value.path.name == name
    assert "\n" not in str(caught.value)


def test_a_folder_that_is_not_a_run_is_refused(tmp_path: Path) -> None:
    _one_line_error(tmp_path, "config.yaml", r"not found: not a run folder \(pass a folder")
    _one_line_error(tmp_path / "nowhere", "nowhere", r"not found \(pass a run folder")
    (tmp_path / "file.txt").write_text("x")
    _one_line_error(tmp_path / "file.txt", "file.txt", "is a file, not a run folder")


def test_an_unfinished_run_names_its_missing_trajectory(tmp_path: Path) -> None:
    _run(tmp_path)
    (tmp_path / "trajectory.txt").unlink()
    # with or without map.pt, `eslam resume` continues it (from frame 0 without one)
    _one_line_error(tmp_path, "trajectory.txt", rf"continue it with `eslam resume {tmp_path}`")
    (tmp_path / "map.pt").write_bytes(b"")
    _one_line_error(tmp_path, "trajectory.txt", r"continue it with `eslam resume")


def test_metrics_that_are_not_an_object(tmp_path: Path) -> None:
    _run(tmp_path)
    (tmp_path / "metrics.json").write_text("[1, 2]\n")
    _one_line_error(tmp_path, "metrics.json", "is not a JSON object")
