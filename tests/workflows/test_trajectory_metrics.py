"""`eslam ate`'s computation as a function: trajectory_errors on tiny TUM files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eslam.cli import ate
from eslam.errors import ConfigError, InputError
from eslam.io.trajectory import write_tum_trajectory
from eslam.workflows.trajectory_metrics import ALIGNMENTS, trajectory_errors


def _write_tum(path: Path, times: np.ndarray, positions: np.ndarray) -> Path:
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    poses[:, :3, 3] = positions
    write_tum_trajectory(path, times, poses)
    return path


@pytest.fixture
def positions() -> np.ndarray:
    return np.cumsum(np.random.default_rng(0).normal(scale=0.05, size=(20, 3)), axis=0)


def test_a_rigidly_moved_estimate_has_no_error_after_alignment(
    positions: np.ndarray, tmp_path: Path
) -> None:
    rotation = Rotation.from_rotvec([0.2, 0.5, -1.0]).as_matrix()
    gt = _write_tum(tmp_path / "gt.txt", np.arange(20.0), positions)
    est = _write_tum(tmp_path / "est.txt", np.arange(20.0) + 0.003, positions @ rotation.T + 2.0)
    errors = trajectory_errors(gt, est)
    assert errors.ate.pairs == 20 and errors.ate.rmse < 1e-9
    assert errors.rpe is not None and errors.rpe.pairs == 19
    metrics = errors.as_dict()
    assert list(metrics)[:9] == [
        "ate_rmse_cm",
        "ate_mean_cm",
        "ate_median_cm",
        "ate_max_cm",
        "pairs",
        "excluded",
        "scale",
        "align",
        "max_diff_s",
    ]
    assert metrics["align"] == "se3" and metrics["max_diff_s"] == 0.01
    assert metrics["rpe_pairs"] == 19 and list(metrics)[-1] == "rpe_pairs"


def test_sim3_finds_the_scale_of_a_run_folder(positions: np.ndarray, tmp_path: Path) -> None:
    _write_tum(tmp_path / "trajectory_gt.txt", np.arange(20.0), positions)
    _write_tum(tmp_path / "trajectory.txt", np.arange(20.0), 2.0 * positions)
    scaled = trajectory_errors(tmp_path, tmp_path, "sim3")
    assert scaled.ate.rmse < 1e-9 and scaled.as_dict()["scale"] == pytest.approx(0.5)
    assert trajectory_errors(tmp_path, tmp_path, "se3").ate.rmse > 0.01  # se3 cannot scale


def test_without_consecutive_finite_poses_the_ate_stands_alone(
    positions: np.ndarray, tmp_path: Path
) -> None:
    gt = _write_tum(tmp_path / "gt.txt", np.arange(8.0), positions[:8])
    lines = [  # every other pose missing (nan): no pair of finite poses one frame apart
        f"{t} {'nan nan nan' if t % 2 else ' '.join(map(str, positions[t]))} 0 0 0 1"
        for t in range(8)
    ]
    est = tmp_path / "est.txt"
    est.write_text("\n".join(lines) + "\n", encoding="utf-8")
    errors = trajectory_errors(gt, est)
    assert errors.rpe is None and errors.ate.pairs == 4 and errors.ate.excluded == 4
    assert not any(key.startswith("rpe_") for key in errors.as_dict())


def test_errors_name_the_file_and_the_fix(positions: np.ndarray, tmp_path: Path) -> None:
    gt = _write_tum(tmp_path / "gt.txt", np.arange(5.0), positions[:5])
    late = _write_tum(tmp_path / "late.txt", np.arange(5.0) + 0.5, positions[:5])
    with pytest.raises(InputError, match=r"only 0 poses matched within 0\.01 s") as raised:
        trajectory_errors(gt, late)
    assert raised.value.path == late and "--max-diff" in str(raised.value)
    with pytest.raises(InputError, match="not found"):
        trajectory_errors(tmp_path / "missing.txt", gt)
    with pytest.raises(ConfigError, match="unknown alignment 'affine'"):
        trajectory_errors(gt, gt, "affine")


def test_the_cli_offers_the_workflows_alignments() -> None:
    assert ate.ALIGNMENTS == ALIGNMENTS
