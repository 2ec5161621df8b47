"""benchmarks/fused_tsdf_odometry.py: the voxel TSDF it fuses, and that its odometry tracks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.errors import ConfigError
from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.io.trajectory import read_trajectory
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing import write_sevenscenes_sequence
from eslam.testing.scripts import load_script
from eslam.types import Intrinsics

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "fused_tsdf_odometry.py"
CONFIG = Path(__file__).resolve().parents[1] / "configs" / "sevenscenes" / "redkitchen.yaml"
CAMERA = Intrinsics(width=40, height=30, fx=300.0, fy=300.0, cx=20.0, cy=15.0)
TRUNCATION = 0.06
PLANE = 2.0


@pytest.fixture(scope="module")
def script():
    return load_script(SCRIPT)


def _wall_depth() -> torch.Tensor:
    """A wall PLANE metres ahead on the image's left half (x < 0), 0.25 m further on the
    right half (a step)."""
    depth = torch.full((CAMERA.height, CAMERA.width), PLANE)
    depth[:, CAMERA.width // 2 :] += 0.25
    return depth


def _plane_volume(script, fusions: int):
    """A volume around the wall of :func:`_wall_depth`, fused ``fusions`` times from a
    camera at the origin."""
    volume = script.empty_volume(torch.tensor([0.0, 0.0, PLANE]), 0.6, 0.02, TRUNCATION)
    for _ in range(fusions):
        script.fuse(volume, _wall_depth(), CAMERA, torch.eye(4))
    return volume


def test_fused_wall_reads_the_projective_tsdf(script) -> None:
    volume = _plane_volume(script, fusions=2)
    near = [PLANE - 0.03, PLANE, PLANE + 0.03, PLANE - 0.2, PLANE + 0.2]
    points = torch.tensor([[-0.05, 0.0, z] for z in near] + [[0.05, 0.0, PLANE + 0.22]])
    sdf = volume.query(points).sdf
    # In the band: (D - z) / T; in front: free space (1); behind the band: never seen
    # (also behind the near half, where the far half's depth takes the fusion further).
    expected = torch.tensor([0.5, 0.0, -0.5, 1.0, script.UNSEEN, 0.5])
    torch.testing.assert_close(sdf, expected, atol=1e-5, rtol=0)
    # Each fusion counts once where it observes, and nowhere outside the camera's view.
    assert volume.weights.max().item() == 2.0
    beside = torch.tensor([[0.25, 0.0, PLANE - 0.03]])  # the view ends 0.13 m to the side
    assert volume.query(beside).sdf.item() == script.UNSEEN
    with pytest.raises(ValueError, match="colour_weight"):
        volume.query(points, with_rgb=True)


def test_a_view_that_misses_the_volume_changes_nothing(script) -> None:
    volume = _plane_volume(script, fusions=1)
    before = volume.values.clone()
    away = torch.eye(4)
    away[:3, :3] = torch.diag(torch.tensor([-1.0, 1.0, -1.0]))  # looking back, away from the wall
    away[2, 3] = -0.5
    script.fuse(volume, _wall_depth(), CAMERA, away)
    assert torch.equal(volume.values, before)


def test_odometry_follows_the_camera(script, tmp_path: Path, capsys) -> None:
    """Against a camera that stands still at the first pose (a tracker that does not
    move), the odometry's ATE must be far smaller; its trajectory file is the run's."""
    frames = list(generate_sequence(SynthConfig(frames=10, width=160, height=120, seed=3)))
    write_sevenscenes_sequence(tmp_path / "seq", frames)
    truth = np.stack([frame.pose_gt for frame in frames])
    odometry, reference, _ = script.fused_tsdf_odometry(
        CONFIG, tmp_path / "seq", 10, voxel=0.03, extent=6.0, device=torch.device("cpu")
    )
    np.testing.assert_allclose(reference, truth)
    assert odometry.failed == []
    tracked = absolute_trajectory_error(odometry.poses, truth).rmse
    standing = absolute_trajectory_error(np.repeat(truth[:1], 10, axis=0), truth).rmse
    assert standing > 0.02
    assert tracked < 0.003 and tracked < standing / 10
    script.main(
        ["--config", str(CONFIG), "--data", str(tmp_path / "seq"), "--frames", "4",
         "--out", str(tmp_path / "run"), "--voxel", "0.03", "--device", "cpu", "--no-append",
         "tracking.sdf.levels=[500]"]
    )  # fmt: skip
    assert "- overrides: `tracking.sdf.levels=[500]`" in capsys.readouterr().out
    _, written = read_trajectory(tmp_path / "run")
    assert written.shape == (4, 4, 4)
    with pytest.raises(ConfigError, match="robust_scale"):  # overrides reach the config
        script.fused_tsdf_odometry(
            CONFIG, tmp_path / "seq", 4, 0.03, 6.0, torch.device("cpu"), 0,
            ("tracking.sdf.robust_scale=0",),
        )  # fmt: skip
    with pytest.raises(SystemExit, match=r"--frames must be in 2\.\.10"):
        script.fused_tsdf_odometry(CONFIG, tmp_path / "seq", 11, 0.03, 6.0, torch.device("cpu"))
