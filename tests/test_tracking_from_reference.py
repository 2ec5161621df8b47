"""benchmarks/tracking_from_reference.py: reference poses up to the switch, the tracker
after it, and the drift table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.io.trajectory import read_trajectory
from eslam.slam.tracking.base import TrackingResult
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing import write_sevenscenes_sequence
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "tracking_from_reference.py"
CONFIG = Path(__file__).resolve().parents[1] / "configs" / "sevenscenes" / "redkitchen_cpu.yaml"


@pytest.fixture(scope="module")
def script():
    return load_script(SCRIPT)


def _along_x(steps: np.ndarray) -> np.ndarray:
    """Poses at x = cumulative sum of ``steps`` (metres), identity rotation."""
    poses = np.repeat(np.eye(4)[None], len(steps), axis=0)
    poses[:, 0, 3] = np.cumsum(steps)
    return poses


def test_drift_rows_measure_over_travel_from_the_switch(script) -> None:
    reference = _along_x(np.full(41, 0.01))  # 1 cm per frame
    estimate = reference.copy()
    estimate[20:, 0, 3] = reference[19, 0, 3] + 1.1 * (reference[20:, 0, 3] - reference[19, 0, 3])
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    estimate[40, :3, :3] = turn
    rows = script.drift_rows(estimate, reference, switch=20, segment=10)
    # segments 19-29, 29-39, 39-40: 10 % too far; 1 mm more error per frame since 19
    assert rows == [
        "| 19-29 | 10.0 | 11.0 | 1.100 | 1.00 | 0.00 |",
        "| 29-39 | 10.0 | 11.0 | 1.100 | 2.00 | 0.00 |",
        "| 39-40 | 0.0 | 0.0 | - | 2.10 | 90.00 |",
    ]


def test_pull_rows_measure_the_pull_from_each_reference_pose(script) -> None:
    reference = _along_x(np.full(21, 0.01))  # 1 cm per frame
    probed = reference[10:].copy()
    probed[:5, 0, 3] += 0.001  # frames 10-14: 1 mm ahead, a tenth of a step
    probed[5:10, 1, 3] -= 0.002  # frames 15-19: 2 mm sideways
    probed[10, :3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    rows = script.pull_rows(probed, reference, switch=10, segment=5)
    assert rows == [
        "| 10-14 | 10.00 | 1.00 | 1.00 | +0.100 | 0.000 |",
        "| 15-19 | 10.00 | 2.00 | 2.00 | +0.000 | 0.000 |",
        "| 20-20 | 10.00 | 0.00 | 0.00 | +0.000 | 90.000 |",
    ]


class _Recorder:
    """A tracker that returns its starting pose and counts its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def track(self, field, view, initial_pose, generator):
        self.calls += 1
        return TrackingResult(pose=initial_pose, loss=torch.zeros(()))


def test_reference_until_switch_then_the_tracker(script) -> None:
    class State:
        next_frame = 0

    reference = torch.as_tensor(_along_x(np.full(5, 0.01)), dtype=torch.float32)
    after = _Recorder()
    tracker = script.ReferenceUntil(reference, switch=3, state=State(), then=after)
    start = torch.eye(4)
    for index in range(5):
        State.next_frame = index
        result = tracker.track(None, None, start, torch.Generator())
        expected = reference[index] if index < 3 else start
        assert torch.equal(result.pose, expected)
    assert after.calls == 2
    assert tracker.probed == {}


def test_a_probe_tracks_from_each_reference_pose_and_keeps_it(script) -> None:
    class State:
        next_frame = 0

    reference = torch.as_tensor(_along_x(np.full(4, 0.01)), dtype=torch.float32)
    recorder = _Recorder()
    tracker = script.ReferenceUntil(reference, switch=2, state=State(), then=recorder, probe=True)
    for index in range(4):
        State.next_frame = index
        result = tracker.track(None, None, torch.eye(4), torch.Generator())
        assert torch.equal(result.pose, reference[index])
    # the recorder answers its start: the reference pose, not the loop's guess (identity)
    assert sorted(tracker.probed) == [2, 3] and recorder.calls == 2
    assert all(torch.equal(tracker.probed[i], reference[i]) for i in (2, 3))


def test_a_run_takes_the_reference_then_tracks(script, tmp_path: Path, capsys) -> None:
    frames = list(generate_sequence(SynthConfig(frames=8, width=160, height=120, seed=3)))
    write_sevenscenes_sequence(tmp_path / "seq", frames)
    truth = np.stack([frame.pose_gt for frame in frames])
    script.main(
        ["--config", str(CONFIG), "--data", str(tmp_path / "seq"), "--switch", "5",
         "--frames", "8", "--segment", "2", "--out", str(tmp_path / "run"), "--device", "cpu",
         "--no-append", "data.register_colour=false", "mapping.optimise_poses=false",
         "mapping.first_iterations=20"]
    )  # fmt: skip
    out = capsys.readouterr().out
    assert "mapping.optimise_poses=false mapping.first_iterations=20`" in out
    assert "ground-truth poses before frame 5" in out
    assert out.count("\n| 4-6 |") == 1 and out.count("\n| 6-7 |") == 1
    _, poses = read_trajectory(tmp_path / "run")
    assert poses.shape == (8, 4, 4)
    # before the switch: the reference (float32); after it: tracked, close but not equal
    np.testing.assert_allclose(poses[:5], truth[:5], atol=1e-6)
    errors = np.linalg.norm(poses[5:, :3, 3] - truth[5:, :3, 3], axis=1)
    assert errors.max() < 0.01
    assert errors.min() > 1e-6
    assert not (tmp_path / "run" / "probed.txt").exists()
    with pytest.raises(SystemExit, match=r"need 1 <= --switch < --frames <= 8"):
        script.track_from_reference(
            CONFIG, tmp_path / "seq", 8, 8, "cpu", ("data.register_colour=false",)
        )


def test_a_probe_run_keeps_the_reference_and_records_the_tracker(
    script, tmp_path: Path, capsys
) -> None:
    frames = list(generate_sequence(SynthConfig(frames=6, width=160, height=120, seed=4)))
    write_sevenscenes_sequence(tmp_path / "seq", frames)
    truth = np.stack([frame.pose_gt for frame in frames])
    script.main(
        ["--config", str(CONFIG), "--data", str(tmp_path / "seq"), "--switch", "3",
         "--frames", "6", "--segment", "2", "--out", str(tmp_path / "run"), "--device", "cpu",
         "--no-append", "--probe", "data.register_colour=false", "mapping.optimise_poses=false",
         "mapping.first_iterations=20"]
    )  # fmt: skip
    out = capsys.readouterr().out
    assert "ground-truth poses for every frame; from frame 3" in out
    assert out.count("\n| 3-4 |") == 1 and out.count("\n| 5-5 |") == 1
    _, poses = read_trajectory(tmp_path / "run")
    np.testing.assert_allclose(poses, truth, atol=1e-6)  # every frame kept its reference
    probed = read_trajectory(tmp_path / "run" / "probed.txt")[1]
    assert probed.shape == (3, 4, 4)
    pulls = np.linalg.norm(probed[:, :3, 3] - truth[3:, :3, 3], axis=1)
    assert pulls.max() < 0.01
    assert pulls.min() > 1e-6  # the tracker ran: its answers are its own


def test_overrides_may_come_before_options(script) -> None:
    """`... key=value --out DIR other=value` is read as the user meant, not refused."""
    required = ["--config", "c.yaml", "--data", "d", "--switch", "5", "--frames", "9"]
    args = script.parse_args([*required, "a.b=1", "--out", "o", "c.d=2", "--probe"])
    assert args.overrides == ["a.b=1", "c.d=2"]
    assert str(args.out) == "o" and args.probe
