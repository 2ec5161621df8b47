"""The keyframes as places: which look like a frame, and where the frame is if it sees
the same place as one of them (:mod:`eslam.slam.places.features` for the maths).

:class:`PlaceIndex` describes each keyframe once, when it is first asked about (its
global descriptor and ORB features with depth, in its own camera frame), from the
keyframe store's images: nothing is saved with the run, a resumed run describes its
keyframes again and gets the same answers. A keyframe's pose is read from the
trajectory at query time, so poses refined by mapping (or a pose graph) are used as
they are now.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from eslam.config.schema import FeaturesConfig
from eslam.slam.mapping.keyframes import KeyframeStore
from eslam.slam.places.features import (
    INLIER_M,
    Features,
    RigidResult,
    guided_matches,
    mutual_matches,
    orb_features,
    residuals,
    rigid_fit,
    rigid_pose,
    thumbnail,
)


@dataclass(frozen=True, eq=False)
class Place:
    """An image as a place: its global descriptor and its ORB features with depth."""

    descriptor: np.ndarray
    features: Features


def describe(
    rgb: np.ndarray, depth: np.ndarray, store: KeyframeStore, orb: FeaturesConfig
) -> Place:
    """An (H, W, 3) uint8 image with its (H, W) depth in metres as a :class:`Place`
    (the store's camera; ORB features as ``orb`` sets)."""
    return Place(thumbnail(rgb), orb_features(rgb, depth, store.intrinsics, orb))


@dataclass(frozen=True)
class PlaceMatch:
    """A keyframe that may see what the query sees.

    Attributes:
        keyframe: its keyframe id in the store.
        pose: (4, 4) float64 camera-to-world of the query from the matches.
        inliers: matches that agree on ``pose``.
    """

    keyframe: int
    pose: np.ndarray
    inliers: int


class PlaceIndex:
    """The keyframes of ``store`` as places (module doc).

    Args:
        store: the run's keyframe store (its images and, through the trajectory, poses).
        orb: the ORB detector's settings, for keyframes and queries alike.
    """

    def __init__(self, store: KeyframeStore, orb: FeaturesConfig) -> None:
        self.store = store
        self.orb = orb
        self._places: list[tuple[int, Place]] = []  # (frame index, place) by keyframe id

    def places(self) -> list[Place]:
        """Every keyframe of the store as a place, by keyframe id: each described on
        first use; entries whose keyframe id now holds another frame (after a
        rollback) are dropped and described again."""
        frames = self.store.frame_indices
        kept = 0
        while kept < min(len(frames), len(self._places)) and self._places[kept][0] == frames[kept]:
            kept += 1
        del self._places[kept:]
        for j in range(kept, len(frames)):
            rgb = (self.store.rgb(j, "cpu") * 255.0).round().to(torch.uint8).numpy()
            depth = self.store.depth(j, "cpu").numpy()
            self._places.append((frames[j], describe(rgb, depth, self.store, self.orb)))
        return [place for _, place in self._places]

    def alike(self, query: Place, count: int) -> list[tuple[int, float]]:
        """The ``count`` keyframes whose global descriptors correlate most with
        ``query``'s: (keyframe id, similarity), most alike first (ties: older first)."""
        places = self.places()
        if not places:
            return []
        scores = np.stack([place.descriptor for place in places]) @ query.descriptor
        order = np.argsort(-scores, kind="stable")[:count]
        return [(int(k), float(scores[k])) for k in order]

    def locate(
        self, query: Place, k: int, min_inliers: int, seed: int = 0, coarse: int = 0
    ) -> PlaceMatch | None:
        """Where the query's camera is if it sees keyframe ``k``'s place: its features
        matched to the keyframe's, both with depth (the keyframe's placed with its pose
        now), give the pose by a rigid fit in RANSAC (:func:`pose_from_matches`, coarse
        to fine with ``coarse``); None without ``min_inliers`` agreeing matches."""
        place = self.places()[k]
        pose = self.store.trajectory.poses[self.store.frame_indices[k]]
        found = pose_from_matches(query.features, place.features, pose, min_inliers, seed, coarse)
        if found is None:
            return None
        return PlaceMatch(k, found.pose, found.inliers)


def pose_from_matches(
    query: Features,
    reference: Features,
    pose: torch.Tensor,
    min_inliers: int,
    seed: int,
    coarse: int = 0,
) -> RigidResult | None:
    """The query camera's pose from its features matched to those of a reference image
    whose camera-to-world pose is ``pose`` (4, 4), both with depth: the reference's
    matched points placed in the world, a rigid fit in RANSAC (:func:`rigid_pose`,
    samples drawn with ``seed``); None without ``min_inliers`` agreeing matches. With
    ``coarse`` > 0 and more query features than that, coarse to fine first
    (:func:`coarse_to_fine`), and all features matched at once only when that gives
    no pose."""
    placed = pose.detach().cpu().double().numpy()
    if 0 < coarse < len(query):
        found = coarse_to_fine(query, reference, placed, min_inliers, seed, coarse)
        if found is not None:
            return found
    pairs = mutual_matches(query.descriptors, reference.descriptors)
    return _rigid_from_pairs(query, reference, pairs, placed, min_inliers, seed)


def coarse_to_fine(
    query: Features,
    reference: Features,
    placed: np.ndarray,
    min_inliers: int,
    seed: int,
    coarse: int,
    radius: float = INLIER_M,
) -> RigidResult | None:
    """:func:`pose_from_matches` in two steps, as ORB-SLAM tracks (a pose, then a
    search by projection; Mur-Artal et al., T-RO 2015): ``coarse`` of the query's
    features, evenly spread over its list (ORB lists them by pyramid level), matched
    to all of the reference's give a rough pose in RANSAC; then every query feature,
    its point placed by that pose, is matched among the reference's within ``radius``
    of it (:func:`~eslam.slam.places.features.guided_matches`; 3 cm, the distance
    within which a match agrees with a pose, :data:`INLIER_M`), and the pose is fitted
    again twice to the matches within 3 cm of the last one. Each feature meets a
    handful of others instead of all. None when either step has fewer than
    ``min_inliers`` agreeing matches."""
    subset = np.unique(np.linspace(0, len(query) - 1, coarse).round().astype(np.int64))
    pairs = mutual_matches(query.descriptors[subset], reference.descriptors)
    pairs[:, 0] = subset[pairs[:, 0]]
    rough = _rigid_from_pairs(query, reference, pairs, placed, min_inliers, seed)
    if rough is None:
        return None
    world = reference.points @ placed[:3, :3].T + placed[:3, 3]
    moved = query.points @ rough.pose[:3, :3].T + rough.pose[:3, 3]
    pairs = guided_matches(query.descriptors, moved, reference.descriptors, world, radius)
    camera, target = query.points[pairs[:, 0]].astype(np.float64), world[pairs[:, 1]]
    pose = rough.pose
    for _ in range(2):
        agree = residuals(pose, camera, target) < INLIER_M
        if agree.sum() < max(min_inliers, 3):
            return None
        pose = rigid_fit(camera[agree], target[agree])
    inliers = int((residuals(pose, camera, target) < INLIER_M).sum())
    return RigidResult(pose, inliers) if inliers >= min_inliers else None


def _rigid_from_pairs(
    query: Features,
    reference: Features,
    pairs: np.ndarray,
    placed: np.ndarray,
    min_inliers: int,
    seed: int,
) -> RigidResult | None:
    """:func:`rigid_pose` of the matched ``pairs`` with depth on both sides, the
    reference's points placed in the world by ``placed`` (4, 4)."""
    if len(pairs) == 0:
        return None
    camera = query.points[pairs[:, 0]]
    points = reference.points[pairs[:, 1]]
    usable = np.isfinite(points).all(axis=1) & np.isfinite(camera).all(axis=1)
    world = points[usable] @ placed[:3, :3].T + placed[:3, 3]
    return rigid_pose(camera[usable].astype(np.float64), world, min_inliers, seed)


class Places:
    """The run's :class:`PlaceIndex`, shared by whoever asks about places (the tracking
    front end's feature start and its recovery): made again when the run's keyframe
    store is another object (a resumed run, a test that swaps the state).

    Args:
        orb: the ORB detector's settings (``tracking.features``).
    """

    def __init__(self, orb: FeaturesConfig) -> None:
        self.orb = orb
        self._index: PlaceIndex | None = None

    def of(self, store: KeyframeStore) -> PlaceIndex:
        """The index of ``store``'s keyframes."""
        if self._index is None or self._index.store is not store:
            self._index = PlaceIndex(store, self.orb)
        return self._index
