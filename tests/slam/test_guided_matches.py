"""Starting pose from features coarse to fine (``tracking.start_coarse``,
docs/tracking.md "Starting pose"): the guided search equals its reference written on
the whole distance matrix, keeps every feature whose point lies near its match's in
reach and none far beyond, the start from a few features and then all of them guided
lies as near the truth as matching all with all, and it falls back to that when the
few give no pose."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eslam.config import load_config
from eslam.errors import ConfigError
from eslam.geometry.pose import pose_distance
from eslam.slam.places.features import (
    guided_matches,
    mutual_matches_reference,
    orb_features,
    within,
)
from eslam.slam.places.index import coarse_to_fine, pose_from_matches
from eslam.synthetic import SynthConfig, SyntheticSequence
from eslam.workflows.demo import DEMO_CONFIG

ROOM = SynthConfig(
    frames=6, width=320, height=240, seed=0, step_translation=0.02, step_rotation_deg=2.0
)
"""The synthetic room at 320 x 240, 2 cm and 2 degrees a frame."""


def near_ties(rng: np.random.Generator, count: int, radius: float) -> tuple:
    """``count`` descriptors with points and a copy of both a few bits and under
    ``radius`` apart, shuffled, with exact duplicates: many pairs at equal distances."""
    base = rng.integers(0, 256, (count, 32), dtype=np.uint8)
    flips = rng.integers(0, 256, (count, 32), dtype=np.uint8) & rng.choice(
        np.array([0, 1, 2, 4], dtype=np.uint8), (count, 32), p=[0.85, 0.05, 0.05, 0.05]
    )
    order = rng.permutation(count)
    points = rng.uniform(-1, 1, (count, 3))
    moved = points[order] + rng.uniform(-0.5, 0.5, (count, 3)) * radius
    other = base[order] ^ flips
    extra = count // 6
    return (
        base,
        points,
        np.concatenate([other, other[:extra]]),
        np.concatenate([moved, moved[:extra]]),
    )


@pytest.mark.parametrize("radius", [0.1, 0.2, 0.4])
def test_guided_matches_equal_their_reference_on_near_ties(radius: float) -> None:
    rng = np.random.default_rng(1)
    a, points_a, b, points_b = near_ties(rng, 400, radius)
    points_a[::7] = np.nan  # no depth: never matched
    allowed = within(points_a, points_b, radius)
    assert 0 < allowed.mean() < 0.3  # a guided search, not all pairs
    counts = allowed.sum(axis=1)
    assert (counts[::7] == 0).all() and (counts >= 2).any()
    assert (counts == 1).any() or radius > 0.1  # lone candidates, held to unrelated bits
    for ratio in (0.6, 0.8, 1.0):
        fast = guided_matches(a, points_a, b, points_b, radius, ratio)
        reference = mutual_matches_reference(a, b, ratio, allowed)
        assert len(reference) > 5 and np.array_equal(fast, reference)
        assert not np.isin(fast[:, 0], np.arange(0, len(a), 7)).any()
    assert len(guided_matches(a[:1], points_a[:1], b, points_b, radius)) == 0


def test_a_feature_near_its_match_keeps_it_and_one_far_away_loses_it() -> None:
    rng = np.random.default_rng(2)
    a = rng.integers(0, 256, (500, 32), dtype=np.uint8)
    points = rng.uniform(-2, 2, (500, 3))
    radius = 0.05
    direction = rng.normal(size=(500, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    moved = guided_matches(a, points, a, points + 0.95 * radius * direction, radius)
    assert np.array_equal(moved, np.stack([np.arange(500)] * 2, axis=1))
    far = guided_matches(a, points, a, points + 2.5 * radius * direction, radius)
    assert len(far) < 10  # only chance pairs among random descriptors


def features(frame):
    return orb_features(frame.rgb, frame.depth, frame.intrinsics)


def test_the_start_coarse_to_fine_lies_as_near_the_truth_as_all_with_all() -> None:
    room = SyntheticSequence(ROOM)
    reference = room[0]
    known = torch.from_numpy(reference.pose_gt)
    for later in (1, 4):  # 2 cm and 2 degrees, 8 cm and 8 degrees on
        query = room[later]
        first, then = features(query), features(reference)
        every = pose_from_matches(first, then, known, 20, seed=0)
        fine = pose_from_matches(first, then, known, 20, seed=0, coarse=300)
        assert every is not None and fine is not None
        assert fine.inliers >= 0.8 * every.inliers  # the guided search finds as many
        truth = torch.from_numpy(query.pose_gt)
        for found in (every, fine):
            error = pose_distance(torch.from_numpy(found.pose), truth)
            assert float(error[0]) < 0.004 and np.degrees(float(error[1])) < 0.1
        assert coarse_to_fine(first, then, known.numpy(), 20, 0, 300) is not None


def test_too_few_coarse_features_fall_back_to_all_with_all() -> None:
    room = SyntheticSequence(ROOM)
    reference, query = room[0], room[2]
    known = torch.from_numpy(reference.pose_gt)
    first, then = features(query), features(reference)
    assert coarse_to_fine(first, then, known.numpy(), 20, 0, 15) is None  # 15 < 20 matches
    every = pose_from_matches(first, then, known, 20, seed=0)
    fallback = pose_from_matches(first, then, known, 20, seed=0, coarse=15)
    assert every is not None and fallback is not None
    assert np.array_equal(fallback.pose, every.pose) and fallback.inliers == every.inliers


def test_a_negative_coarse_count_is_refused() -> None:
    with pytest.raises(ConfigError, match="start_coarse"):
        load_config(DEMO_CONFIG, ["tracking.start_coarse=-1"])
