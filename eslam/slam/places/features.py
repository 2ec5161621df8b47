"""Image features for place recognition (OpenCV): a global descriptor per image, local
features with their depth, matching, and a camera pose from matches.

- The global descriptor is the *small blurry image* of Klein and Murray (ECCV 2008,
  "Improving the agility of keyframe-based SLAM"), the relocaliser of PTAM: the grey
  image shrunk to :data:`THUMBNAIL` pixels (``cv2.resize``, area averaging), blurred
  (``cv2.GaussianBlur``, sigma 2.5 thumbnail pixels), then made zero-mean and unit-norm,
  so that the dot product of two is their normalised cross-correlation (1 = alike).
  It needs no vocabulary trained beforehand and costs microseconds per keyframe; it
  ranks keyframes, it does not decide: the matches and the map do.
- Local features are ORB (Rublee et al., ICCV 2011; ``cv2.ORB_create``), matched by
  Hamming distance with Lowe's ratio test (IJCV 2004) and kept where both ways agree;
  given a rough pose, among the features near where it puts each one only
  (:func:`guided_matches`).
  How many, and how faint a corner may be (``tracking.features``), decide whether a
  blurred frame (a fast turn) keeps enough of them to match.
- A pose from matches: the keyframe's features with depth give world points, the
  frame's features with its own depth camera points; a rigid motion fitted in RANSAC
  (:func:`rigid_pose`) carries one onto the other. Camera axes are OpenCV's, as
  everywhere in eslam.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from eslam.config.schema import FeaturesConfig
from eslam.types import Intrinsics

THUMBNAIL = (40, 30)
"""Width and height of the small blurry image (Klein and Murray use 40 x 30)."""

BLUR_SIGMA = 2.5
"""Gaussian blur of the small image, in its pixels (Klein and Murray: 2.5)."""

FLAT_GREY = 0.01
"""RMS contrast (grey levels of 255) below which a small image counts as flat."""

RATIO = 0.8
"""Lowe's ratio: a match is kept when its distance is below this times the second best."""

INLIER_M = 0.03
"""Distance (metres) within which a match agrees with a rigid pose."""

UNRELATED_BITS = 128
"""Bits two unrelated ORB descriptors differ in, about half of 256: the second nearest a
guided search holds a descriptor with one candidate to (:func:`guided_matches`)."""

RANSAC_ITERATIONS = 200
"""Three-point samples tried per pose."""


def opencv() -> Any:
    """The ``cv2`` module (opencv-python-headless, a dependency of eslam)."""
    import cv2

    return cv2


def grey(rgb: np.ndarray) -> np.ndarray:
    """(H, W) uint8 luminance of an (H, W, 3) uint8 RGB image (ITU-R BT.601 weights)."""
    return opencv().cvtColor(np.ascontiguousarray(rgb), opencv().COLOR_RGB2GRAY)


def thumbnail(rgb: np.ndarray) -> np.ndarray:
    """The global descriptor of an (H, W, 3) uint8 image: (40 * 30,) float32, zero mean
    and unit norm (module doc); all zeros for a flat image (alike to nothing)."""
    cv2 = opencv()
    small = cv2.resize(grey(rgb), THUMBNAIL, interpolation=cv2.INTER_AREA).astype(np.float32)
    small = cv2.GaussianBlur(small, (0, 0), BLUR_SIGMA)
    vector = small.reshape(-1) - small.mean()
    norm = float(np.linalg.norm(vector))
    if norm < FLAT_GREY * np.sqrt(vector.size):  # only the blur's round-off is left
        return np.zeros_like(vector)
    return vector / norm


@dataclass(frozen=True, eq=False)
class Features:
    """An image's ORB features.

    Attributes:
        pixels: (N, 2) float32 keypoint positions (x, y) in pixels.
        descriptors: (N, 32) uint8 ORB descriptors.
        points: (N, 3) float32 camera-frame points q = d (x - cx) / fx, ... at the
            keypoints' depth (nearest pixel); NaN where the depth is missing.
    """

    pixels: np.ndarray
    descriptors: np.ndarray
    points: np.ndarray

    def __len__(self) -> int:
        return len(self.pixels)


def orb_features(
    rgb: np.ndarray,
    depth: np.ndarray,
    intrinsics: Intrinsics,
    settings: FeaturesConfig | None = None,
) -> Features:
    """The ORB features (``settings``, default ``tracking.features``'s defaults) of an
    (H, W, 3) uint8 image with its (H, W) depth in metres (0 = missing), back-projected
    with ``intrinsics``."""
    cv2 = opencv()
    settings = FeaturesConfig() if settings is None else settings
    orb = cv2.ORB_create(nfeatures=settings.count, fastThreshold=settings.fast_threshold)
    keypoints, descriptors = orb.detectAndCompute(grey(rgb), None)
    if descriptors is None or not keypoints:
        empty = np.zeros((0, 2), np.float32)
        return Features(empty, np.zeros((0, 32), np.uint8), np.zeros((0, 3), np.float32))
    pixels = np.array([k.pt for k in keypoints], dtype=np.float32)
    cols = np.clip(np.rint(pixels[:, 0]).astype(int), 0, depth.shape[1] - 1)
    rows = np.clip(np.rint(pixels[:, 1]).astype(int), 0, depth.shape[0] - 1)
    z = depth[rows, cols].astype(np.float32)
    z = np.where(z > 0, z, np.nan)
    x = (pixels[:, 0] - intrinsics.cx) / intrinsics.fx * z
    y = (pixels[:, 1] - intrinsics.cy) / intrinsics.fy * z
    return Features(pixels, descriptors, np.stack([x, y, z], axis=1))


def mutual_matches(a: np.ndarray, b: np.ndarray, ratio: float = RATIO) -> np.ndarray:
    """(M, 2) int index pairs (into ``a``, into ``b``) of ORB descriptors that pass the
    ratio test from ``a`` to ``b`` and are each other's nearest both ways.

    Only the descriptors of ``b`` that some match passing the ratio test points to are
    matched back to ``a``: each one's nearest in ``a`` does not depend on the others, so
    the pairs are those of matching all of ``b`` back (:func:`mutual_matches_reference`)
    in less time."""
    if len(a) < 2 or len(b) < 2:
        return np.zeros((0, 2), np.int64)
    cv2 = opencv()
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    passed = [
        (pair[0].queryIdx, pair[0].trainIdx)
        for pair in matcher.knnMatch(a, b, k=2)
        if len(pair) == 2 and pair[0].distance < ratio * pair[1].distance
    ]
    if not passed:
        return np.zeros((0, 2), np.int64)
    targets = np.unique([t for _, t in passed])
    nearest = {int(targets[m.queryIdx]): m.trainIdx for m in matcher.match(b[targets], a)}
    pairs = [(q, t) for q, t in passed if nearest.get(t) == q]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def mutual_matches_reference(
    a: np.ndarray, b: np.ndarray, ratio: float = RATIO, allowed: np.ndarray | None = None
) -> np.ndarray:
    """:func:`mutual_matches` written out on the whole Hamming distance matrix (slow, and
    N x M x 256 bytes of memory: for tests, which hold the two equal): a's nearest and
    second nearest in b by distance, then index (the lowest index wins a tie, as
    OpenCV's brute-force matcher keeps it), the ratio test, and b's nearest in a.
    ``allowed`` (N, M) bool: only those pairs are compared (:func:`guided_matches`);
    a descriptor of ``a`` with one allowed is held to :data:`UNRELATED_BITS` as its
    second nearest, and one with none has no match."""
    if len(a) < 2 or len(b) < 2:
        return np.zeros((0, 2), np.int64)
    bits = np.unpackbits(a[:, None, :] ^ b[None, :, :], axis=2)
    distance = bits.sum(axis=2, dtype=np.int64)
    allowed = np.ones(distance.shape, bool) if allowed is None else allowed
    distance = np.where(allowed, distance, np.iinfo(np.int64).max)
    order = np.argsort(distance, axis=1, kind="stable")
    rows = np.arange(len(a))
    best, second = distance[rows, order[:, 0]], distance[rows, order[:, 1]]
    back = np.argmin(distance, axis=0)
    candidates = allowed.sum(axis=1)
    second = np.where(candidates == 1, UNRELATED_BITS, second)
    keep = (candidates >= 1) & (best < ratio * second) & (back[order[:, 0]] == rows)
    return np.stack([rows[keep], order[keep, 0]], axis=1).astype(np.int64)


def within(points_a: np.ndarray, points_b: np.ndarray, radius: float) -> np.ndarray:
    """(N, M) bool: whether the (N, 3) and (M, 3) points (NaN: none) lie within
    ``radius`` of each other: the pairs :func:`guided_matches` compares."""
    gap = np.linalg.norm(points_a[:, None, :] - points_b[None, :, :], axis=2)
    return np.nan_to_num(gap, nan=np.inf) <= radius


def guided_matches(
    a: np.ndarray,
    points_a: np.ndarray,
    b: np.ndarray,
    points_b: np.ndarray,
    radius: float,
    ratio: float = RATIO,
) -> np.ndarray:
    """(M, 2) index pairs as :func:`mutual_matches` finds them, each descriptor compared
    only with those whose point lies within ``radius`` of its own, both sets of (N, 3)
    points placed in one frame by a pose known roughly (NaN: no depth, no match): a
    guided search (ORB-SLAM's search by projection, Mur-Artal et al., T-RO 2015, here
    in 3D), where each feature meets a handful of others instead of all. The ratio test
    and the check both ways run among those; a descriptor with one to compare is held
    to :data:`UNRELATED_BITS` as its second nearest. Equal to
    :func:`mutual_matches_reference` with ``allowed=within(points_a, points_b, radius)``."""
    empty = np.zeros((0, 2), np.int64)
    if len(a) < 2 or len(b) < 2:
        return empty
    usable_a = np.nonzero(np.isfinite(points_a).all(axis=1))[0]
    usable_b = np.nonzero(np.isfinite(points_b).all(axis=1))[0]
    if len(usable_a) == 0 or len(usable_b) == 0:
        return empty
    close = cKDTree(points_a[usable_a]).sparse_distance_matrix(
        cKDTree(points_b[usable_b]), radius, output_type="ndarray"
    )
    rows, cols = usable_a[close["i"]], usable_b[close["j"]]
    distance = np.bitwise_count(a[rows] ^ b[cols]).sum(axis=1, dtype=np.int64)
    # by row, then distance, then index (one int64 key: a stable three-key sort's order)
    order = np.argsort((rows * 257 + distance) * len(b) + cols)
    rows, cols, distance = rows[order], cols[order], distance[order]
    first = np.nonzero(np.r_[True, rows[1:] != rows[:-1]])[0]
    lone = np.r_[first[1:], len(rows)] - first == 1
    second = np.where(lone, UNRELATED_BITS, distance[np.minimum(first + 1, len(rows) - 1)])
    passed = first[distance[first] < ratio * second]
    back = np.argsort((cols * 257 + distance) * len(a) + rows)  # by column, distance, index
    heads = back[np.r_[True, cols[back][1:] != cols[back][:-1]]]
    nearest = np.full(len(b), -1, np.int64)
    nearest[cols[heads]] = rows[heads]
    keep = passed[nearest[cols[passed]] == rows[passed]]
    return np.stack([rows[keep], cols[keep]], axis=1).astype(np.int64)


@dataclass(frozen=True)
class RigidResult:
    """A camera pose from matches: (4, 4) float64 camera-to-world and the inlier count."""

    pose: np.ndarray
    inliers: int


def rigid_fit(camera: np.ndarray, world: np.ndarray) -> np.ndarray:
    """(4, 4) the rigid motion T = [R t] minimising sum |R q_i + t - p_i|^2 over (N, 3)
    ``camera`` points q and ``world`` points p, N >= 3 (Arun, Huang and Blostein, PAMI
    1987): R solves Wahba's problem on the centred points
    (``scipy.spatial.transform.Rotation.align_vectors``), t = mean(p) - R mean(q).
    Nearly collinear points leave R poorly defined: scipy's warning about it is
    silenced, as RANSAC's inlier count judges such a sample anyway."""
    q_mean, p_mean = camera.mean(axis=0), world.mean(axis=0)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Optimal rotation is not uniquely")
        rotation, _ = Rotation.align_vectors(world - p_mean, camera - q_mean)
    pose = np.eye(4)
    pose[:3, :3] = rotation.as_matrix()
    pose[:3, 3] = p_mean - pose[:3, :3] @ q_mean
    return pose


def rigid_fits(camera: np.ndarray, world: np.ndarray) -> np.ndarray:
    """(S, 4, 4) :func:`rigid_fit` of each of S point sets, (S, N, 3) ``camera`` and
    ``world`` points, at once: the Kabsch solution (Kabsch, Acta Cryst. A 1976; Arun et
    al. 1987) R = V diag(1, 1, d) U^T from the SVD U S V^T of the centred points'
    covariance H = sum q_i p_i^T, d = sign det(V U^T) so that R is a rotation, not a
    reflection; t = mean(p) - R mean(q). Equal to :func:`rigid_fit` wherever the
    points are not collinear (there R is not defined by them)."""
    q_mean, p_mean = camera.mean(axis=1), world.mean(axis=1)
    covariance = np.einsum("sni,snj->sij", camera - q_mean[:, None], world - p_mean[:, None])
    u, _, vt = np.linalg.svd(covariance)
    flip = np.ones((len(camera), 3))
    flip[:, 2] = np.sign(np.linalg.det(np.einsum("sji,skj->sik", vt, u)))
    rotation = np.einsum("sji,sj,skj->sik", vt, flip, u)
    poses = np.tile(np.eye(4), (len(camera), 1, 1))
    poses[:, :3, :3] = rotation
    poses[:, :3, 3] = p_mean - np.einsum("sij,sj->si", rotation, q_mean)
    return poses


def rigid_pose(
    camera: np.ndarray,
    world: np.ndarray,
    min_inliers: int,
    seed: int = 0,
    threshold_m: float = INLIER_M,
    iterations: int = RANSAC_ITERATIONS,
) -> RigidResult | None:
    """The camera-to-world pose that carries the (N, 3) ``camera`` points (the frame's
    matched features with its depth) onto their matches' (N, 3) ``world`` points: RANSAC
    (Fischler and Bolles 1981) over fits of 3 matches (:func:`rigid_fit`; samples drawn
    with ``seed``), an inlier being within ``threshold_m``, then refitted on the best
    sample's inliers; None with fewer than ``min_inliers`` inliers. The samples are
    fitted and scored at once (:func:`rigid_fits`), as a loop over them with
    :func:`rigid_fit` would (``tests/slam/test_recovery.py`` holds the two equal).

    With depth on both sides this is better posed than a perspective-n-point pose from
    pixels, which on a few dozen features of a room's planes often flips."""
    count = len(camera)
    if count < max(min_inliers, 3):
        return None
    generator = np.random.default_rng(seed)
    samples = np.stack([generator.choice(count, size=3, replace=False) for _ in range(iterations)])
    spread = np.linalg.svd(world[samples] - world[samples].mean(axis=1, keepdims=True))[1]
    samples = samples[(spread > 1e-3).sum(axis=1) >= 2]  # collinear: no rotation about their line
    if len(samples) == 0:
        return None
    poses = rigid_fits(camera[samples], world[samples])
    offsets = camera @ poses[:, :3, :3].transpose(0, 2, 1) + poses[:, None, :3, 3] - world
    agree = np.einsum("sni,sni->sn", offsets, offsets) < threshold_m**2  # (samples, N)
    best = agree[int(np.argmax(agree.sum(axis=1)))]  # the first sample with the most
    if best.sum() < max(min_inliers, 3):
        return None
    pose = rigid_fit(camera[best], world[best])
    inliers = residuals(pose, camera, world) < threshold_m
    if inliers.sum() < min_inliers:
        return None
    return RigidResult(pose, int(inliers.sum()))


def residuals(pose: np.ndarray, camera: np.ndarray, world: np.ndarray) -> np.ndarray:
    """(N,) distances |R q_i + t - p_i| in metres."""
    return np.linalg.norm(camera @ pose[:3, :3].T + pose[:3, 3] - world, axis=1)
