"""The synthetic loop (``eslam synth --trajectory loop``) and the drift option
(``--focal-error``): exact ground truth for what loop closure must fix."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from eslam.cli import main
from eslam.data.replica import ReplicaSequence
from eslam.synthetic import SynthConfig, camera_trajectory
from eslam.synthetic.scenes import build_scene
from eslam.synthetic.sequence import SyntheticSequence
from eslam.synthetic.trajectory import loop_lap_frames


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2
    return math.degrees(math.acos(np.clip(cosine, -1.0, 1.0)))


def test_the_loop_leaves_and_comes_back() -> None:
    config = SynthConfig(frames=300, trajectory="loop")
    scene = build_scene(config.scene, config.seed)
    poses = camera_trajectory(scene, config)
    lap = loop_lap_frames(scene, config)
    assert 150 < lap < 300
    # back where it began (the bob's few centimetres aside), looking the same way ...
    assert np.linalg.norm(poses[lap, :3, 3] - poses[0, :3, 3]) < 0.03
    assert _angle_deg(poses[lap], poses[0]) < 2.0
    # ... after a long excursion that looked the other way
    half = lap // 2
    assert np.linalg.norm(poses[half, :3, 3] - poses[0, :3, 3]) > 0.5
    assert _angle_deg(poses[half], poses[0]) > 150.0
    steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    assert abs(steps.mean() - config.step_translation) < 0.002
    assert np.all(np.abs(poses[:, 2, 3] - (scene.camera_lo[2] + scene.camera_hi[2]) / 2) < 0.06)
    # frame i does not depend on the sequence's length
    np.testing.assert_array_equal(
        camera_trajectory(scene, SynthConfig(frames=40, trajectory="loop")), poses[:40]
    )


def test_a_focal_error_changes_the_reported_camera_only() -> None:
    exact = SyntheticSequence(SynthConfig(frames=1, width=64, height=48))
    biased = SyntheticSequence(SynthConfig(frames=1, width=64, height=48, focal_error=0.02))
    assert biased.intrinsics.fx == exact.intrinsics.fx * 1.02
    assert biased.intrinsics.cx == exact.intrinsics.cx
    np.testing.assert_array_equal(biased[0].depth, exact[0].depth)
    np.testing.assert_array_equal(biased[0].pose_gt, exact[0].pose_gt)


def test_synth_writes_the_loop_with_its_drift(tmp_path: Path) -> None:
    out = tmp_path / "loop"
    arguments = ["--trajectory", "loop", "--focal-error", "0.01", "--depth-noise"]
    assert main(["synth", str(out), "--frames", "3", "--size", "64x48", *arguments]) == 0
    sequence = ReplicaSequence(out)
    exact = SyntheticSequence(SynthConfig(frames=3, width=64, height=48, trajectory="loop"))
    assert math.isclose(sequence.intrinsics.fx, exact.intrinsics.fx * 1.01, rel_tol=1e-6)
    np.testing.assert_allclose(sequence[2].pose_gt, exact[2].pose_gt, atol=1e-6)
    written = json.loads((out / "synth.json").read_text())["config"]
    assert written["trajectory"] == "loop" and written["focal_error"] == 0.01
