"""Loop closure in whole runs (``mapping.loops``): the camera walks out through the
synthetic room and back the way it came; the return is registered to the keyframes of
the way out, loops are recorded in loops.json (written from the first checkpoint on,
empty before any candidate), closed through the pose graph, and a run stopped right
after a closure resumes to the same trajectory and loop record."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from eslam.config import load_config
from eslam.data.replica import ReplicaSequence
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig
from eslam.synthetic.edits import SequenceEdit, write_edited_sequence
from tests.conftest import demo_config, static_ate_cm

pytest.importorskip("gtsam", reason="the loops extra (GTSAM) is not installed")

ROOM = SynthConfig(frames=10, width=120, height=90, seed=0)
ORDER = (*range(10), *range(8, 0, -2))  # out to frame 9, back to frame 2 two at a time
LOOPS = (
    "mapping.loops.enabled=true",
    "mapping.loops.min_keyframes_back=3",
    "mapping.loops.min_correction=0.0",  # close every accepted loop (none is needed here)
    "mapping.loops.min_correction_deg=0.0",
)


@pytest.fixture(scope="module")
def there_and_back(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("loops") / "room"
    return write_edited_sequence(out, ROOM, SequenceEdit(ORDER))


def _record(run: Path) -> list[dict]:
    return json.loads((run / "loops.json").read_text())


@pytest.mark.slow
def test_the_return_is_closed_and_a_resumed_run_ends_the_same(
    there_and_back: Path, tmp_path: Path
) -> None:
    config = demo_config(there_and_back, *LOOPS)
    whole = run_slam(config, tmp_path / "whole")
    record = _record(tmp_path / "whole")
    closed = [e for e in record if e.get("closed")]
    assert closed and all(e["accepted"] for e in closed)
    assert {e["candidate_frame"] for e in closed} <= {0, 4}
    assert whole.metrics["loops_closed"] == len(closed)
    log = (tmp_path / "whole" / "log.txt").read_text()
    assert "loop closed: frame" in log and "pose graph and map refit" in log
    sequence = ReplicaSequence(there_and_back)
    gt = np.stack([sequence[i].pose_gt for i in range(len(ORDER))])
    assert whole.metrics["ate_rmse_cm"] < min(1.0, 0.1 * static_ate_cm(gt))

    stopped = tmp_path / "stopped"
    run_slam(config, stopped, stop_after=3)
    assert _record(stopped) == []  # loop closure on, nothing far enough back yet
    first = closed[0]["frame"]
    run_slam(load_config(stopped / "config.yaml"), stopped, resume=True, stop_after=first + 1)
    assert _record(stopped) == [e for e in record if e["frame"] <= first]
    resumed = run_slam(load_config(stopped / "config.yaml"), stopped, resume=True)
    np.testing.assert_allclose(resumed.poses, whole.poses, rtol=0, atol=1e-7)
    assert _record(stopped) == record


@pytest.mark.slow
def test_a_map_rebuilt_after_the_correction_tracks_the_return(
    there_and_back: Path, tmp_path: Path
) -> None:
    """``mapping.loops.map: rebuild``: a new field, its TSDF regressed on every keyframe
    at its corrected pose, then fitted; the frames after the closure track on it."""
    config = demo_config(there_and_back, *LOOPS, "mapping.loops.map=rebuild")
    run = run_slam(config, tmp_path / "rebuilt")
    assert run.metrics["loops_closed"] >= 1
    sequence = ReplicaSequence(there_and_back)
    gt = np.stack([sequence[i].pose_gt for i in range(len(ORDER))])
    assert run.metrics["ate_rmse_cm"] < min(1.0, 0.1 * static_ate_cm(gt))


@pytest.mark.slow
def test_the_global_refinement_moves_frames_with_their_keyframes(
    there_and_back: Path, tmp_path: Path
) -> None:
    """``final_passes``: passes over every keyframe with their poses optimised at the end,
    timed and logged; every frame moves with the latest keyframe at or before it, and a
    run resumed after it does not refine again."""
    plain = ("mapping.loops.enabled=true", "mapping.loops.candidates=0")
    before = run_slam(demo_config(there_and_back, *plain), tmp_path / "plain")
    config = demo_config(there_and_back, *plain, "mapping.loops.final_passes=1")
    after = run_slam(config, tmp_path / "refined")
    assert "loops_refinement_s" not in before.metrics
    assert after.metrics["loops_refinement_s"] > 0
    assert "global refinement: 1 passes over" in (tmp_path / "refined" / "log.txt").read_text()
    keyframes = [0, 4, 8, 12, 13]  # the demo maps every 4th frame and the last
    moved = np.abs(after.poses[keyframes[1:]] - before.poses[keyframes[1:]]).max()
    assert 1e-5 < moved < 0.05  # refined, not thrown away
    for f in range(len(ORDER)):  # every frame keeps its offset to its keyframe
        k = max(k for k in keyframes if k <= f)
        np.testing.assert_allclose(
            np.linalg.inv(after.poses[k]) @ after.poses[f],
            np.linalg.inv(before.poses[k]) @ before.poses[f],
            atol=1e-6,
        )
    sequence = ReplicaSequence(there_and_back)
    gt = np.stack([sequence[i].pose_gt for i in range(len(ORDER))])
    assert after.metrics["ate_rmse_cm"] < min(1.0, 0.1 * static_ate_cm(gt))
    again = run_slam(
        load_config(tmp_path / "refined" / "config.yaml"), tmp_path / "refined", resume=True
    )
    np.testing.assert_allclose(again.poses, after.poses, rtol=0, atol=1e-9)
    assert (tmp_path / "refined" / "log.txt").read_text().count("global refinement") == 1
