"""Starts from image features when the map or the latest images fail them: a start of
features overrules the tracker when the map pulls the camera far from it
(``tracking.start_overrule_*``, docs/tracking.md "When the features overrule the map"):
the rule on its own (matches, shift, frames in a row), and a run on the synthetic room
with exact ground truth whose tracker is pulled 8 cm off on chosen frames: those frames
keep their features' pose (within a centimetre of the truth), count failed and
overruled, and say so in the log; without the rule they land 8 cm off (a little less
where mapping refines them); a run stopped in the middle of the overruled frames resumes
to the same poses. And a frame that matches neither the previous frame nor the latest
keyframe starts from the keyframe that looks alike and most matches agree on
(``tracking.start_alike``)."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from eslam.errors import ConfigError
from eslam.slam.places.index import PlaceMatch
from eslam.slam.session import run_slam
from eslam.slam.state import quality_row
from eslam.slam.tracking.base import TrackingQuality, TrackingResult
from eslam.slam.tracking.feature_start import (
    FeatureStart,
    FeatureStartResult,
    OverruleRule,
    start_shift,
)
from eslam.slam.tracking.trackers import TRACKERS
from eslam.synthetic import SynthConfig
from eslam.synthetic.edits import SequenceEdit, write_edited_sequence
from tests.conftest import demo_config

RULE = OverruleRule(matches=100, shift=0.05, frames=2)


def rows(*overruled: bool) -> SimpleNamespace:
    """A run's state as the rule reads it: quality rows, the frames overruled or not."""
    quality = TrackingQuality(10, 0.8, 0.004, failed=False)
    return SimpleNamespace(
        tracking_quality=[quality_row(replace(quality, overruled=o)) for o in overruled]
    )


def start(inliers: int) -> FeatureStartResult:
    return FeatureStartResult(torch.eye(4, dtype=torch.float64), reference=0, inliers=inliers)


def passed(shift: float | None) -> TrackingQuality:
    """A passed frame whose tracker moved the camera ``shift`` metres from its start."""
    return TrackingQuality(10, 0.8, 0.004, failed=False, start_shift_m=shift)


def test_the_shift_is_the_distance_between_camera_centres() -> None:
    pose = torch.eye(4)
    pose[:3, :3] = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    pose[:3, 3] = torch.tensor([0.03, -0.04, 0.0])
    assert start_shift(start(150), pose) == pytest.approx(0.05)


def test_the_rule_needs_matches_a_shift_and_a_passed_frame() -> None:
    features = FeatureStart(places=None, min_matches=20, overrule=RULE)  # type: ignore[arg-type]
    state = rows(False)
    assert features.overrules(start(150), passed(0.06), state)
    for found, quality in [
        (start(150), passed(0.04)),  # moved less than the shift
        (start(99), passed(0.06)),  # too few matches agree
        (start(150), dataclasses.replace(passed(None), failed=True)),  # the tracker failed
    ]:
        assert not features.overrules(found, quality, state)
    never = FeatureStart(places=None, min_matches=20)  # type: ignore[arg-type]
    assert not never.overrules(start(150), passed(0.06), state)


def test_the_features_overrule_at_most_frames_in_a_row() -> None:
    features = FeatureStart(places=None, min_matches=20, overrule=RULE)  # type: ignore[arg-type]
    # frames in a row overruled just before (the quality rows): two are allowed
    fired = [
        features.overrules(start(150), passed(0.06), before)
        for before in (rows(), rows(True), rows(True, True), rows(True, True, False))
    ]
    assert fired == [True, True, False, True]


ROOM = SynthConfig(
    frames=8, width=160, height=120, seed=0, step_translation=0.02, step_rotation_deg=2.0
)
"""The synthetic room, 2 cm and 2 degrees a frame."""
PULLED = (3, 4)
"""The frames on which the map pulls the camera away."""
PULL = 0.08
"""How far, metres."""


class PulledAway:
    """The SDF tracker, with its answer for the frames in :data:`PULLED` moved 8 cm
    along x and judged passed: a map that pulls the camera to a wrong pose. Counts its
    calls across instances (call k tracks frame k; a resumed run builds a new one)."""

    calls = 0

    def __init__(self, config) -> None:
        self.real = TRACKERS.make("sdf", config)

    def track(self, field, view, initial_pose, generator):
        PulledAway.calls += 1
        result = self.real.track(field, view, initial_pose, generator)
        if PulledAway.calls not in PULLED:
            return result
        pose = result.pose.clone()
        pose[0, 3] += PULL
        return TrackingResult(pose, result.loss, dataclasses.replace(result.quality, failed=False))


@pytest.fixture(scope="module")
def room(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("overrule") / "room"
    return write_edited_sequence(out, ROOM, SequenceEdit(tuple(range(ROOM.frames))))


def pulled_config(room: Path, *extra: str):
    config = demo_config(room, "tracking.start=features", *extra)
    return dataclasses.replace(
        config, tracking=dataclasses.replace(config.tracking, method="pulled")
    )


def errors(run: Path) -> np.ndarray:
    estimate = np.loadtxt(run / "trajectory.txt")[:, 1:4]
    truth = np.loadtxt(run / "trajectory_gt.txt")[:, 1:4]
    return np.linalg.norm(estimate - truth, axis=1)


@pytest.mark.slow
def test_a_map_that_pulls_the_camera_away_is_overruled_by_the_features(
    room: Path, tmp_path: Path, register
) -> None:
    register(TRACKERS, "pulled", PulledAway)
    PulledAway.calls = 0
    # few matches in a 160x120 image: the rule asks for 20 here (300 by default)
    config = pulled_config(room, "tracking.start_overrule_matches=20")
    result = run_slam(config, tmp_path / "run")
    assert result.metrics["tracking_overruled"] == len(PULLED)
    assert result.metrics["tracking_failures"] == len(PULLED)
    assert errors(tmp_path / "run").max() < 0.01
    timings = json.loads((tmp_path / "run" / "timings.json").read_text())
    assert [timings["tracking_failed"][i] for i in (2, 3, 4, 5)] == [0.0, 1.0, 1.0, 0.0]
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "frame 3 (timestamp 3.000000): the map moved the camera 8." in log
    assert "the features' pose is kept and the frame is no keyframe" in log
    # each frame's start, per frame: the matches and how far the tracker moved from it
    assert all(matches >= 20 for matches in timings["tracking_start_matches"][1:])
    shifts = timings["tracking_start_shift_m"]
    assert [shifts[i] > 0.07 for i in range(1, ROOM.frames)] == [i in PULLED for i in range(1, 8)]

    # stopped after frame 3 (mid-way through the overruled frames), resumed
    PulledAway.calls = 0
    stopped = tmp_path / "stopped"
    run_slam(config, stopped, stop_after=4)
    resumed = run_slam(config, stopped, resume=True)
    assert resumed.metrics["tracking_overruled"] == len(PULLED)
    np.testing.assert_allclose(resumed.poses, result.poses, rtol=0, atol=1e-7)

    # without the rule the pulled frames keep the map's pose, 8 cm off
    PulledAway.calls = 0
    off = run_slam(pulled_config(room, "tracking.start_overrule_matches=0"), tmp_path / "off")
    assert off.metrics["tracking_overruled"] == 0
    assert off.metrics["tracking_failures"] == 0
    assert errors(tmp_path / "off")[list(PULLED)].min() > 0.04  # the map refines some back


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("tracking.start_overrule_matches=-1", "start_overrule_matches"),
        ("tracking.start_overrule_shift=0", "start_overrule_shift"),
        ("tracking.start_overrule_frames=0", "start_overrule_frames"),
    ],
)
def test_bad_overrule_settings_are_refused(room: Path, override: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        demo_config(room, override)


class Keyframes:
    """The keyframe store as the feature start reads it: frame indices by keyframe id."""

    def __init__(self, frames: list[int]) -> None:
        self.frame_indices = frames

    def __len__(self) -> int:
        return len(self.frame_indices)


class LookAlike:
    """A place index whose keyframes ``inliers`` agree with the query (None: no pose),
    ranked alike in ``order``; records the keyframes it was asked to locate."""

    def __init__(self, inliers: dict[int, int | None], order: list[int]) -> None:
        self.inliers, self.order, self.located = inliers, order, []

    def of(self, store):
        return self

    def alike(self, query, count: int) -> list[tuple[int, float]]:
        return [(k, 1.0 - 0.1 * rank) for rank, k in enumerate(self.order[:count])]

    def locate(
        self, query, k: int, min_inliers: int, seed: int = 0, coarse: int = 0
    ) -> PlaceMatch | None:
        self.located.append(k)
        found = self.inliers[k]
        if found is None or found < min_inliers:
            return None
        return PlaceMatch(k, np.eye(4) * (k + 1), found)


@pytest.mark.parametrize("alike", [0, 2])
def test_keyframes_that_look_alike_start_a_frame_the_latest_one_cannot(alike: int) -> None:
    """Keyframes 0-3 at frames 0, 5, 10, 15; the frame (20) has no previous frame's
    features kept and matches nothing of the latest keyframe (3); of the two most alike
    besides it (2 and 0; 1 is third) keyframe 0 has the most agreeing matches."""
    index = LookAlike({0: 80, 1: 500, 2: 40, 3: None}, order=[3, 2, 0, 1])
    features = FeatureStart(index, min_matches=20, alike=alike)  # type: ignore[arg-type]
    state = SimpleNamespace(next_frame=20, components={}, keyframes=Keyframes([0, 5, 10, 15]))
    found = features.matched(query=None, state=state)  # type: ignore[arg-type]
    if alike == 0:
        assert found is None and index.located == [3]
        return
    assert index.located == [3, 2, 0]  # the latest first, then the alike ones but it
    assert found is not None
    assert (found.reference, found.inliers, found.source) == (0, 80, "alike_keyframe")
    assert torch.equal(found.pose, torch.from_numpy(np.eye(4)))


SHIFT = 0.06
"""How far the shifted tracker's frame lies from the mapper's, metres: more than the
rule's 5 cm."""


class Shifted:
    """The SDF tracker with every answer moved :data:`SHIFT` along x: a tracker whose
    optimum lies that far from the mapper's (``tracking.keyframe_offset`` takes its poses
    back into the mapper's frame)."""

    def __init__(self, config) -> None:
        self.real = TRACKERS.make("sdf", config)

    def track(self, field, view, initial_pose, generator):
        result = self.real.track(field, view, initial_pose, generator)
        pose = result.pose.clone()
        pose[0, 3] += SHIFT
        return TrackingResult(pose, result.loss, result.quality)


@pytest.mark.slow
def test_the_shift_is_measured_in_the_mappers_frame(room: Path, tmp_path: Path, register) -> None:
    """With the keyframe offset a frame's start of features is chained from poses in the
    mapper's frame, so the tracker's answer is compared with it after the offset: taken
    before, a tracker 6 cm from the mapper would be overruled on every frame it may be."""
    register(TRACKERS, "shifted", Shifted)
    config = demo_config(
        room,
        "tracking.start=features",
        "tracking.start_overrule_matches=20",
        "tracking.keyframe_offset=true",
    )
    config = dataclasses.replace(
        config, tracking=dataclasses.replace(config.tracking, method="shifted")
    )
    result = run_slam(config, tmp_path / "run")
    assert result.metrics["tracking_keyframe_offsets"] >= 1
    assert result.metrics["tracking_overruled"] == 0
    assert errors(tmp_path / "run").max() < 0.01  # the offset took the shift back
    shifts = json.loads((tmp_path / "run" / "timings.json").read_text())["tracking_start_shift_m"]
    assert max(shifts[1:]) < 0.02
