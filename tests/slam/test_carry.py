"""Frames between keyframes follow the keyframes' refined poses (``mapping.carry_frames``)."""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path

import pytest
import torch

from eslam.geometry.pose import interpolate_pose, invert, se3_exp
from eslam.slam.mapping.backend import BACK_ENDS, KeyframeBackEnd
from eslam.slam.mapping.carry import carried_poses, corrections
from eslam.slam.session import run_slam
from tests.conftest import tiny_config


def _poses(count: int) -> torch.Tensor:
    """A camera moving 1 cm and turning 1 degree a frame."""
    step = se3_exp(torch.tensor([0.01, 0.0, 0.0, 0.0, math.radians(1.0), 0.0], dtype=torch.float64))
    poses = [torch.eye(4, dtype=torch.float64)]
    for _ in range(count - 1):
        poses.append(poses[-1] @ step)
    return torch.stack(poses)


def _shift(x: float) -> torch.Tensor:
    shift = torch.eye(4, dtype=torch.float64)
    shift[0, 3] = x
    return shift


def test_frames_between_keyframes_share_their_corrections_linearly() -> None:
    poses = _poses(9)
    frames, carried = carried_poses(poses, [0, 4, 8], {4: _shift(0.04)})
    assert frames == [1, 2, 3, 5, 6, 7]  # keyframes are not touched
    moved = (carried[:, :3, 3] - poses[frames, :3, 3])[:, 0]
    # C_4 is a pure translation: frame f moves by its share of it, 0 at a held keyframe
    assert moved.tolist() == pytest.approx([0.01, 0.02, 0.03, 0.03, 0.02, 0.01], abs=1e-12)
    assert torch.allclose(carried[:, :3, :3], poses[frames, :3, :3], atol=1e-12)


def test_equal_corrections_move_a_stretch_rigidly() -> None:
    poses = _poses(9)
    turn = se3_exp(torch.tensor([0.02, -0.01, 0.03, 0.01, 0.02, -0.03], dtype=torch.float64))
    frames, carried = carried_poses(poses, [0, 4, 8], {0: turn, 4: turn, 8: turn})
    assert frames == [1, 2, 3, 5, 6, 7]
    assert torch.allclose(carried, turn @ poses[frames], atol=1e-12)


def test_a_frame_blends_its_two_keyframes_on_the_geodesic() -> None:
    poses = _poses(5)
    a = se3_exp(torch.tensor([0.02, 0.0, 0.0, 0.0, 0.0, 0.05], dtype=torch.float64))
    b = se3_exp(torch.tensor([0.0, 0.01, 0.0, 0.04, 0.0, 0.0], dtype=torch.float64))
    frames, carried = carried_poses(poses, [0, 4], {0: a, 4: b})
    assert frames == [1, 2, 3]
    for row, f in enumerate(frames):
        expected = interpolate_pose(a @ poses[f], b @ poses[f], f / 4)
        assert torch.allclose(carried[row], expected, atol=1e-12)
    # a frame next to a keyframe moves almost as that keyframe does
    assert torch.allclose(carried[0], a @ poses[1], atol=0.02)


def test_frames_after_the_last_keyframe_move_with_it() -> None:
    poses = _poses(7)
    frames, carried = carried_poses(poses, [0, 4], {4: _shift(0.05)})
    assert frames == [1, 2, 3, 5, 6]
    assert torch.allclose(carried[3:], _shift(0.05) @ poses[5:], atol=1e-12)


def test_nothing_moved_carries_nothing_and_bad_keyframes_are_refused() -> None:
    poses = _poses(6)
    frames, carried = carried_poses(poses, [0, 3], {})
    assert frames == [] and carried.shape == (0, 4, 4)
    with pytest.raises(ValueError, match="must increase"):
        carried_poses(poses, [3, 0], {3: _shift(0.01)})
    before, after = poses[:2], _shift(0.01) @ poses[:2]
    assert torch.allclose(corrections(before, after), _shift(0.01).expand(2, 4, 4), atol=1e-12)
    assert torch.allclose(invert(poses[3]) @ poses[3], torch.eye(4, dtype=torch.float64))


class Watching(KeyframeBackEnd):
    """The paper's back end, recording the trajectory around every mapping result."""

    calls: typing.ClassVar[list] = []

    def apply(self, job, result, state) -> None:
        before = state.trajectory.poses.clone()
        super().apply(job, result, state)
        after = state.trajectory.poses.clone()
        Watching.calls.append((job.window, state.keyframes.frame_indices, before, after))


@pytest.mark.slow
@pytest.mark.parametrize("carry", [False, True])
def test_a_run_carries_frames_exactly_when_asked(
    carry: bool, tiny_sequence: Path, tmp_path: Path, register, monkeypatch: pytest.MonkeyPatch
) -> None:
    register(BACK_ENDS, "watching", Watching)
    monkeypatch.setattr(Watching, "calls", [])
    config = tiny_config(tiny_sequence, "output.mesh=false", f"mapping.carry_frames={carry}")
    config = dataclasses.replace(
        config, mapping=dataclasses.replace(config.mapping, back_end="watching")
    )
    run_slam(config, tmp_path / "run")
    assert len(Watching.calls) > 2
    carried_any = False
    for window, keyframes, before, after in Watching.calls:
        others = [f for f in range(len(before)) if f not in keyframes]
        if not carry:  # mapping moves keyframes only
            assert torch.equal(before[others], after[others])
            continue
        moved = {
            k: c
            for k, c in zip(
                window,
                corrections(before[list(window)].double(), after[list(window)].double()),
                strict=True,
            )
            if not torch.equal(before[k], after[k])
        }
        frames, expected = carried_poses(before.double(), keyframes, moved)
        assert torch.allclose(after[frames].double(), expected, atol=1e-5)
        assert torch.equal(
            before[[f for f in others if f not in frames]],
            after[[f for f in others if f not in frames]],
        )
        if frames:
            shift = (after[frames] - before[frames]).abs().max()
            carried_any = carried_any or bool(shift > 1e-5)
    assert carried_any == carry
