"""Loop closure (eslam.slam.loops) on keyframes of the synthetic loop with exact ground
truth: a drifted estimate that returns to its start is pulled back (a true loop is
accepted and shrinks the error); a keyframe that looks like the start but is another
place is refused; ICP and the candidate rules on their own."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
import torch

from eslam.config import load_config
from eslam.slam.context import RunContext
from eslam.slam.loops.candidates import far_enough
from eslam.slam.loops.closer import LoopCloser, anchor_sigmas, loop_metrics, pose_difference
from eslam.slam.loops.icp import register
from eslam.slam.loops.pose_graph import relative_pose
from eslam.slam.run.observers import RunObserverBase
from eslam.slam.state import initial_state
from eslam.synthetic import SynthConfig, SyntheticSequence
from eslam.synthetic.scenes import build_scene
from eslam.synthetic.trajectory import loop_lap_frames
from eslam.types import Frame
from eslam.workflows.demo import DEMO_CONFIG

pytest.importorskip("gtsam", reason="the loops extra (GTSAM) is not installed")

LOOP = SynthConfig(frames=400, width=120, height=90, trajectory="loop")
LAP = loop_lap_frames(build_scene(LOOP.scene, LOOP.seed), LOOP)
SEQUENCE = SyntheticSequence(LOOP)
EVERY = 4


def _yaw(degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    pose = np.eye(4)
    pose[:2, :2] = [[c, -s], [s, c]]
    return pose


def _closer_and_state(estimates: list[np.ndarray], keyframes: dict[int, Frame], *settings):
    """A run's state holding ``estimates`` (frame i's pose) and ``keyframes`` (frame
    index -> the frame stored as its keyframe), and a loop closer whose map refits are
    counted instead of run."""
    config = load_config(
        DEMO_CONFIG,
        ["mapping.loops.enabled=true", "mapping.loops.min_keyframes_back=40", *settings],
    )
    context = RunContext.build(
        config,
        torch.device("cpu"),
        SEQUENCE.intrinsics,
        RunObserverBase(),
        logging.getLogger("test_loop_closure"),
        "synthetic loop",
    )
    state = initial_state(config, SEQUENCE.intrinsics, torch.device("cpu"))
    for i, pose in enumerate(estimates):
        state.trajectory.append(torch.from_numpy(pose).float(), i / 30.0, SEQUENCE[i].pose_gt)
    for index, frame in sorted(keyframes.items()):
        state.keyframes.add(frame, index)
    refits: list[int] = []
    closer = LoopCloser(context, lambda s, moved: refits.append((s.next_frame, len(moved))))
    return closer, state, refits


def _errors(state, count: int) -> np.ndarray:
    poses = state.trajectory.poses[:count].double().numpy()
    return np.array(
        [np.linalg.norm(poses[i, :3, 3] - SEQUENCE[i].pose_gt[:3, 3]) for i in range(count)]
    )


def test_a_drifted_return_is_closed_and_the_error_shrinks() -> None:
    """The estimate turns 0.03 degrees a frame too far about the room's centre (about
    7 degrees and 6 cm off on the way back to the start); the returning keyframe is
    registered to the first, the graph spreads the correction and every frame moves
    with its keyframe."""
    count = LAP + 1
    estimates = [_yaw(0.03 * i) @ SEQUENCE[i].pose_gt for i in range(count)]
    keyframes = {i: SEQUENCE[i] for i in range(0, count, EVERY)}
    keyframes[LAP] = SEQUENCE[LAP]
    closer, state, refits = _closer_and_state(estimates, keyframes)
    before = _errors(state, count)
    closer.after_keyframe(LAP, len(state.keyframes) - 1, state)
    after = _errors(state, count)
    entries = state.components["loops"]["entries"]
    closed = [e for e in entries if e.get("closed")]
    assert len(closed) == 1 and closed[0]["candidate_frame"] <= 12 * EVERY
    assert closed[0]["correction_deg"] > 5.0
    ((frames, moved),) = refits  # one refit, of the keyframes the correction moved
    assert frames == count and 0 < moved <= len(state.keyframes)
    assert before[-1] > 0.04 and after[-1] < 0.005
    assert np.sqrt(np.mean(after**2)) < 0.5 * np.sqrt(np.mean(before**2))
    metrics = loop_metrics(state)
    assert metrics.pop("loops_time_s") > 0
    assert metrics == {
        "loops_accepted": sum(e["accepted"] for e in entries),
        "loops_rejected": len(entries) - sum(e["accepted"] for e in entries),
        "loops_closed": 1,
    }


def test_measured_odometry_takes_out_an_error_the_estimate_holds() -> None:
    """The drifting estimate above, with a stretch mid-lap also 3 cm off (a step in and
    a step out, as where the tracker followed a map it had drifted with): the
    estimate's odometry edges hold the steps, so closing the loop with them leaves the
    stretch off; the edges measured by ICP (``odometry: icp``, no anchors) do not."""
    count = LAP + 1
    shift = np.eye(4)
    shift[:3, 3] = [0.03, 0.0, 0.0]
    stretch = range(LAP // 3, LAP // 2)
    estimates = [_yaw(0.03 * i) @ SEQUENCE[i].pose_gt for i in range(count)]
    for i in stretch:
        estimates[i] = shift @ estimates[i]
    keyframes = {i: SEQUENCE[i] for i in range(0, count, EVERY)}
    keyframes[LAP] = SEQUENCE[LAP]
    errors, metrics = {}, {}
    for odometry in ("estimate", "icp"):
        closer, state, refits = _closer_and_state(
            estimates,
            keyframes,
            f"mapping.loops.odometry={odometry}",
            "mapping.loops.anchor_sigma=null",
        )
        closer.after_keyframe(LAP, len(state.keyframes) - 1, state)
        assert len(refits) == 1
        errors[odometry] = _errors(state, count)
        metrics[odometry] = loop_metrics(state)
    held, measured = (errors[o][list(stretch)].mean() for o in ("estimate", "icp"))
    assert held > 0.02 and measured < 0.5 * held
    assert np.sqrt(np.mean(errors["icp"] ** 2)) < np.sqrt(np.mean(errors["estimate"] ** 2))
    assert "loops_odometry_measured" not in metrics["estimate"]
    kept, refused = (
        metrics["icp"][k] for k in ("loops_odometry_measured", "loops_odometry_refused")
    )
    assert kept + refused == len(keyframes) - 1 and kept > 0.9 * (len(keyframes) - 1)


def test_a_look_alike_is_refused_and_nothing_moves() -> None:
    """Half a lap on, the camera looks the other way; its keyframe is given the first
    frame's colour over its own depth: it looks like the start (appearance proposes the
    start) but is another place, so the registration is refused."""
    count = LAP // 2 + 1
    estimates = [SEQUENCE[i].pose_gt for i in range(count)]
    keyframes = {i: SEQUENCE[i] for i in range(0, count - 1, EVERY // 2)}
    other = SEQUENCE[count - 1]
    keyframes[count - 1] = Frame(
        other.index, SEQUENCE[0].rgb, other.depth, other.intrinsics, other.pose_gt, other.timestamp
    )
    closer, state, refits = _closer_and_state(estimates, keyframes)
    before = state.trajectory.poses[:count].clone()
    closer.after_keyframe(count - 1, len(state.keyframes) - 1, state)
    entries = state.components["loops"]["entries"]
    assert any(e["candidate_frame"] == 0 and e["found_by"] == "appearance" for e in entries)
    assert entries and not any(e["accepted"] for e in entries)
    assert all(e["why_not"] for e in entries)
    assert refits == [] and torch.equal(state.trajectory.poses[:count], before)


def test_icp_recovers_a_relative_pose_and_tells_a_wrong_one() -> None:
    a, b = SEQUENCE[0], SEQUENCE[LAP + 2]
    truth = relative_pose(b.pose_gt, a.pose_gt)  # a's camera to b's
    start = _yaw(4.0) @ truth
    start[:3, 3] += [0.03, -0.02, 0.01]
    found = register(a.depth, b.depth, SEQUENCE.intrinsics, start, greys=_greys(a, b))
    metres, degrees = pose_difference(truth, found.pose)
    assert metres < 0.002 and degrees < 0.05
    assert found.inlier_fraction > 0.8 and found.residual < 0.002
    assert found.colour_agreement > 0.9
    # the room's far side turned round: a box fits itself (over half the points on its
    # surface), but its texture does not
    c = SEQUENCE[LAP // 2]
    opposite = register(a.depth, c.depth, SEQUENCE.intrinsics, start, greys=_greys(a, c))
    assert opposite.colour_agreement < 0.6


@pytest.mark.parametrize("back", [27, 23, 19, 15])
def test_icp_takes_enough_points_of_a_small_noisy_image(back: int) -> None:
    """At 160x120 with a sensor's noise and holes (the loop benchmark's frames), the
    default stride (every pixel there) brings the return's relative pose within 6 mm and
    0.2 degrees; every 4th pixel (the stride of a 640x480 image) does not."""
    noisy = SynthConfig(
        frames=LAP, width=160, height=120, trajectory="loop", depth_noise=True, missing_depth=True
    )
    sequence = SyntheticSequence(noisy)
    a, b = sequence[LAP - back], sequence[0]
    truth = relative_pose(b.pose_gt, a.pose_gt)
    start = _yaw(1.0) @ truth
    start[:3, 3] += [0.02, -0.01, 0.01]
    found = register(a.depth, b.depth, sequence.intrinsics, start)
    metres, degrees = pose_difference(truth, found.pose)
    assert metres < 0.006 and degrees < 0.2


def _greys(*frames: Frame) -> tuple[np.ndarray, ...]:
    return tuple(f.rgb.mean(axis=-1) / 255.0 for f in frames)


def test_anchors_widen_to_twice_a_large_correction() -> None:
    """A loop within the anchors keeps them; one that shows the tracker further off
    (drift that added up, as in the test above) widens them to twice its correction."""
    assert anchor_sigmas(None, 0.5, 30.0) is None
    assert anchor_sigmas((0.01, 0.02), 0.005, 0.2) == (0.01, 0.02)
    rotation, translation = anchor_sigmas((0.01, 0.02), 0.06, 7.0)
    assert rotation == pytest.approx(2 * math.radians(7.0)) and translation == pytest.approx(0.12)


def test_candidates_lie_far_enough_back() -> None:
    config = load_config(DEMO_CONFIG, ["mapping.loops.min_keyframes_back=5"]).mapping.loops
    line = np.stack([np.array([0.1 * k, 0.0, 0.0]) for k in range(10)])  # 0.9 m of path
    assert far_enough(line, 9, config) == [0, 1, 2, 3, 4]
    long = np.stack([np.array([1.0 * k, 0.0, 0.0]) for k in range(10)])  # 1 m a keyframe
    assert far_enough(long, 9, config) == list(range(8))  # 2 m back: keyframe 7 too
