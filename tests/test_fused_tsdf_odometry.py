"""benchmarks/fused_tsdf_odometry.py: the voxel TSDF it fuses, and that its odometry tracks."""

from __future__ import annotations

import dataclasses
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


def test_removing_a_fused_image_undoes_it(script) -> None:
    once = _plane_volume(script, fusions=1)
    volume = _plane_volume(script, fusions=1)
    shifted = torch.eye(4)
    shifted[0, 3] = 0.05  # another view of the wall, 5 cm to the side
    script.fuse(volume, _wall_depth() + 0.01, CAMERA, shifted)
    assert not torch.allclose(volume.values, once.values)
    script.fuse(volume, _wall_depth() + 0.01, CAMERA, shifted, remove=True)
    torch.testing.assert_close(volume.values, once.values, atol=1e-6, rtol=0)
    assert torch.equal(volume.weights, once.weights)
    script.fuse(volume, _wall_depth(), CAMERA, torch.eye(4), remove=True)  # nothing left
    assert bool((volume.values == script.UNSEEN).all()) and bool((volume.weights == 0).all())


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


def _sequence(tmp_path: Path, shorten_from: int | None = None) -> Path:
    """The synthetic room's first 10 frames as a 7-Scenes folder; with ``shorten_from``,
    the depth of that frame and the later ones read 1 % short (a depth the reference
    poses disagree with)."""
    frames = list(generate_sequence(SynthConfig(frames=10, width=160, height=120, seed=3)))
    if shorten_from is not None:
        frames = [
            dataclasses.replace(frame, depth=frame.depth * 0.99) if i >= shorten_from else frame
            for i, frame in enumerate(frames)
        ]
    write_sevenscenes_sequence(tmp_path / "seq", frames)
    return tmp_path / "seq"


def test_probe_on_exact_data_stays_at_the_reference(script, tmp_path: Path) -> None:
    data = _sequence(tmp_path)
    probe = script.probe_reference(CONFIG, data, 5, 10, 0.03, 6.0, torch.device("cpu"))
    assert probe.probed.shape == (5, 4, 4) and len(probe.residuals) == 5
    pulls = np.linalg.norm(probe.probed[:, :3, 3] - probe.reference[5:, :3, 3], axis=1)
    assert pulls.max() < 0.003  # 3 cm voxels: their interpolation moves the surface ~2 mm
    assert all(abs(r.median) < 0.001 and abs(r.far) < 0.001 for r in probe.residuals)


def test_probe_measures_a_depth_the_reference_disagrees_with(script, tmp_path: Path) -> None:
    """Frames 5-9 read 1 % short: at their reference poses their points lie in front of
    the surface frames 0-4 fused (positive residuals, more on the far half), and the
    tracker pulls the camera towards the surface. A probe that did not track, or read
    the volume at the wrong pose, would report no pull or no residual."""
    data = _sequence(tmp_path, shorten_from=5)
    probe = script.probe_reference(CONFIG, data, 5, 10, 0.03, 6.0, torch.device("cpu"))
    pulls = np.linalg.norm(probe.probed[:, :3, 3] - probe.reference[5:, :3, 3], axis=1)
    assert np.median(pulls) > 0.01
    assert all(r.median > 0.01 and r.far > r.near for r in probe.residuals)
    with pytest.raises(SystemExit, match="--probe < --frames"):
        script.probe_reference(CONFIG, data, 10, 10, 0.03, 6.0, torch.device("cpu"))
    # On a volume of the last 2 frames only, frames 7-9 agree with it again: their
    # predecessors there are 1 % short as they are (what --keep tells apart: a reference
    # consistent with the depth over a short span but not since frame 0).
    recent = script.probe_reference(CONFIG, data, 5, 10, 0.03, 6.0, torch.device("cpu"), keep=2)
    near = np.linalg.norm(recent.probed[:, :3, 3] - recent.reference[5:, :3, 3], axis=1)
    assert near[2:].max() < 0.005 < 0.01 < pulls[2:].min()
    assert abs(recent.residuals[-1].median) < 0.001


def test_residual_rows_take_medians_over_the_segment(script) -> None:
    ninths = np.arange(9, dtype=float).reshape(3, 3) / 1000
    residuals = [
        script.FrameResidual(0.001 * k, -0.002, 0.003 * k, ninths + 0.001 * k) for k in range(3)
    ]
    residuals[2] = script.FrameResidual(0.002, -0.002, float("nan"), np.full((3, 3), np.nan))
    rows = script.residual_rows(residuals, switch=20, segment=2)
    assert rows[0] == (
        "| 20-21 | +0.5 | -2.0 | +1.5 | +0.5 +1.5 +2.5 / +3.5 +4.5 +5.5 / +6.5 +7.5 +8.5 |"
    )
    assert rows[1].startswith("| 22-22 | +2.0 | -2.0 | +nan |")


def test_probe_command_writes_the_answers_and_tables(script, tmp_path: Path, capsys) -> None:
    data = _sequence(tmp_path)
    script.main(
        ["--config", str(CONFIG), "--data", str(data), "--frames", "6", "--probe", "3",
         "--segment", "2", "--out", str(tmp_path / "run"), "--voxel", "0.03",
         "--device", "cpu", "--no-append", "tracking.sdf.levels=[500]"]
    )  # fmt: skip
    out = capsys.readouterr().out
    assert "| 3-4 |" in out and "| 5-5 |" in out and "by ninth of the image" in out
    _, probed = read_trajectory(tmp_path / "run" / "probed.txt")
    assert probed.shape == (3, 4, 4)
    with pytest.raises(SystemExit):
        script.main(["--config", str(CONFIG), "--data", str(data), "--frames", "6",
                     "--probe", "3", "--segment", "0", "--out", str(tmp_path / "x")])  # fmt: skip
    with pytest.raises(SystemExit):  # --keep goes with --probe
        script.main(["--config", str(CONFIG), "--data", str(data), "--frames", "6",
                     "--keep", "3", "--out", str(tmp_path / "x")])  # fmt: skip
