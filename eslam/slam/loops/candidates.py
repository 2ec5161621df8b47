"""Which earlier keyframes may see what the new keyframe sees (loop candidates).

A keyframe qualifies by distance along the run: at least ``min_keyframes_back``
keyframes back, or at least ``min_travel`` metres back along the path of the keyframes'
positions. Among those, candidates come two ways:

- **by pose**: the share of the new keyframe's depth points, placed with the current
  estimate, that fall inside the keyframe's view (the mapping window's overlap test,
  :meth:`~eslam.slam.mapping.windows.OverlapWindow.overlap_fractions`), at least
  ``min_overlap``; this finds the place while the drift is smaller than a view;
- **by appearance**: the global image descriptor (:class:`~eslam.slam.places.index.PlaceIndex`,
  PTAM's small blurry image by OpenCV), most alike first, whose ORB matches with depth
  then give a first relative pose; this finds the place when drift has moved the
  estimate out of the view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from eslam.config.schema import LoopClosureConfig
from eslam.slam.mapping.keyframes import KeyframeStore
from eslam.slam.mapping.windows import OverlapWindow
from eslam.slam.places.index import PlaceIndex

MIN_FEATURE_INLIERS = 12
"""ORB matches that must agree on an appearance candidate's first relative pose."""


@dataclass(frozen=True)
class Candidate:
    """An earlier keyframe to register the new one to.

    Attributes:
        keyframe: its keyframe id.
        found_by: "pose" or "appearance".
        guess: (4, 4) float64 the new keyframe's camera-to-world pose to start from
            (the estimate, or where the feature matches put it).
        score: overlap share (pose) or descriptor similarity (appearance).
    """

    keyframe: int
    found_by: str
    guess: np.ndarray
    score: float


def far_enough(positions: np.ndarray, current: int, config: LoopClosureConfig) -> list[int]:
    """Keyframe ids before ``current`` that lie ``min_keyframes_back`` keyframes or
    ``min_travel`` metres of path back; ``positions`` (K, 3) by keyframe id."""
    steps = np.linalg.norm(np.diff(positions[: current + 1], axis=0), axis=1)
    travelled_after = np.concatenate([np.cumsum(steps[::-1])[::-1], [0.0]])  # from k to current
    return [
        k
        for k in range(current)
        if current - k >= config.min_keyframes_back or travelled_after[k] >= config.min_travel
    ]


def by_pose(
    store: KeyframeStore,
    current: int,
    eligible: list[int],
    config: LoopClosureConfig,
    generator: torch.Generator | None,
) -> list[Candidate]:
    """The ``config.candidates`` eligible keyframes that see most of the new one."""
    if not eligible or config.candidates == 0:
        return []
    overlap = OverlapWindow(size=3, samples=256)
    fractions = overlap.overlap_fractions(store, current, eligible, generator)
    if fractions is None:
        return []
    shares = fractions.cpu().numpy()
    order = np.argsort(-shares, kind="stable")[: config.candidates]
    guess = store.poses[current].detach().cpu().double().numpy()
    return [
        Candidate(eligible[i], "pose", guess, float(shares[i]))
        for i in order
        if shares[i] >= config.min_overlap
    ]


def by_appearance(
    places: PlaceIndex, current: int, eligible: list[int], config: LoopClosureConfig, seed: int
) -> tuple[list[Candidate], list[tuple[int, float]]]:
    """The ``config.candidates`` keyframes of ``eligible`` (those not already candidates
    by pose) that look most like the new one and whose features give a relative pose;
    and those that looked alike but gave none (keyframe, similarity)."""
    if not eligible or config.candidates == 0:
        return [], []
    allowed = set(eligible)
    query = places.places()[current]
    ranked = [(k, s) for k, s in places.alike(query, len(places.places())) if k in allowed]
    found, refused = [], []
    for k, similarity in ranked[: config.candidates]:
        match = places.locate(query, k, MIN_FEATURE_INLIERS, seed)
        if match is None:
            refused.append((k, similarity))
        else:
            found.append(Candidate(k, "appearance", match.pose, similarity))
    return found, refused
