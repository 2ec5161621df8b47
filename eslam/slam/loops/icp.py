"""Projective point-to-plane ICP between two depth images: the relative pose of a loop.

KinectFusion's registration (Newcombe et al., ISMAR 2011, section 3.4; the linearisation
of Low, "Linear least-squares optimization for point-to-plane ICP", 2004). Source points
p_i (the query keyframe's depth, back-projected and subsampled) are moved by the
estimate T (source camera to target camera), projected into the target image and paired
with the target's vertex v and normal n at that pixel. Each step minimises

    sum_i w_i (n_i . (R p_i + t - v_i))^2

linearised in a small twist xi = (a, b) (rotation a, translation b) applied on the left,
T <- exp(xi) T:  r_i + [(T p_i) x n_i; n_i] . xi, with Huber weights w_i on the residual
and pairs farther apart than the step's distance gate, or whose normals disagree, left
out. The gate shrinks over the steps (coarse to fine). Normals come from the cross
product of the vertex map's horizontal and vertical central differences.

What verifies a loop is the result's agreement: the share of the source points that
land on the target's surface (within ``inlier_distance``, normals agreeing), the RMS of
their point-to-plane residuals, and the smallest eigenvalue of the normal equations
(a plane or a corridor leaves a direction unconstrained).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from eslam.types import Intrinsics


@dataclass(frozen=True)
class IcpSettings:
    """Projective ICP's settings (metres; module doc).

    Attributes:
        stride: take every stride-th source pixel in each direction; None = one per
            160 pixels of image width (4 at 640x480, 1 at 160x120: about 19,000 source
            points whatever the image size; a small noisy image's every 4th pixel
            leaves too few points for a loop's relative pose, docs/results.md "Loop
            closure").
        normal_step: normals from differences this many pixels either side; None =
            one per 128 pixels of image width (a sensor's noise is per pixel, so a
            larger image needs a longer baseline: 5 at 640x480, 1 at 160x120).
        gates: distance gate of each step, coarse to fine (its length is the steps).
        inlier_distance: a pair closer than this (and normals agreeing) is an inlier.
        min_normal_cosine: normals of a pair must agree at least this well.
        huber: residual scale of the Huber weights.
        colour_tolerance: a pair's colours agree when their grey values, less the
            median difference over the inliers (an exposure change), differ by less
            than this (grey in [0, 1]).
    """

    stride: int | None = None
    normal_step: int | None = None
    gates: tuple[float, ...] = (0.2, 0.2, 0.1, 0.1, 0.05, 0.05, 0.03, 0.03, 0.02, 0.02)
    inlier_distance: float = 0.02
    min_normal_cosine: float = 0.8
    huber: float = 0.01
    colour_tolerance: float = 0.1


@dataclass(frozen=True)
class IcpResult:
    """The registration and how well it agrees.

    Attributes:
        pose: (4, 4) source camera to target camera (p_target = pose @ p_source).
        inlier_fraction: inliers over the source points that project into the target's
            view onto a pixel with depth (the overlap's points).
        overlap: source points that project inside the target image with depth there,
            over the source points with depth.
        residual: RMS point-to-plane residual of the inliers, metres.
        min_eigenvalue: smallest eigenvalue of the last step's normal equations, per
            inlier (m^2 for translation; small: a direction is not constrained).
        colour_agreement: share of the inliers whose colours agree (settings'
            ``colour_tolerance``): geometry that fits but shows another texture is
            another place (a box-shaped room fits itself turned round); nan without
            colour images.
    """

    pose: np.ndarray
    inlier_fraction: float
    overlap: float
    residual: float
    min_eigenvalue: float
    colour_agreement: float = math.nan


def vertex_map(depth: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) camera-frame points of a depth image (metres; 0 depth gives 0 points)."""
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    z = depth.astype(np.float64)
    x = (u - intrinsics.cx) / intrinsics.fx * z
    y = (v - intrinsics.cy) / intrinsics.fy * z
    return np.stack([x, y, z], axis=-1)


def normal_map(vertices: np.ndarray, step: int = 1) -> np.ndarray:
    """(H, W, 3) unit normals from central differences of ``vertices`` ``step`` pixels
    either side (a longer baseline averages a noisy sensor's depth), facing the camera;
    zero where a neighbour has no depth or the cross product vanishes."""
    s = step
    dx = np.zeros_like(vertices)
    dy = np.zeros_like(vertices)
    dx[:, s:-s] = vertices[:, 2 * s :] - vertices[:, : -2 * s]
    dy[s:-s] = vertices[2 * s :] - vertices[: -2 * s]
    valid = vertices[..., 2] > 0
    neighbours = np.zeros_like(valid)
    neighbours[s:-s, s:-s] = (
        valid[s:-s, 2 * s :]
        & valid[s:-s, : -2 * s]
        & valid[2 * s :, s:-s]
        & valid[: -2 * s, s:-s]
        & valid[s:-s, s:-s]
    )
    normals = np.cross(dx, dy)
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    ok = neighbours & (length[..., 0] > 1e-12)
    normals = np.where(ok[..., None], normals / np.maximum(length, 1e-12), 0.0)
    facing = np.sum(normals * vertices, axis=-1) > 0  # pointing away from the camera
    normals[facing] *= -1.0
    return normals


def _twist_matrix(xi: np.ndarray) -> np.ndarray:
    """exp of the twist (a, b) as a 4x4 (rotation by Rodrigues, translation b; the
    first-order pairing of a small step)."""
    a, b = xi[:3], xi[3:]
    angle = float(np.linalg.norm(a))
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    if angle < 1e-12:
        rotation = np.eye(3) + k
    else:
        k_unit = k / angle
        rotation = np.eye(3) + np.sin(angle) * k_unit + (1 - np.cos(angle)) * k_unit @ k_unit
    step = np.eye(4)
    step[:3, :3] = rotation
    step[:3, 3] = b
    return step


@dataclass(frozen=True)
class _Pairs:
    moved: np.ndarray  # (P, 3) source points in the target camera
    normals: np.ndarray  # (P, 3) target normals at their pixels
    residuals: np.ndarray  # (P,) point-to-plane residuals
    pairs: np.ndarray  # (P,) bool: paired within the gate, normals agreeing
    overlap: float
    u: np.ndarray  # (P,) target pixel column of each point (0 where outside)
    v: np.ndarray  # (P,) target pixel row


class _Images:
    """The source points and the target's vertex and normal maps, built once."""

    def __init__(
        self, source_depth, target_depth, intrinsics: Intrinsics, stride: int, normal_step: int
    ):
        source = vertex_map(source_depth, intrinsics)
        normals = normal_map(source, normal_step)[::stride, ::stride].reshape(-1, 3)
        points = source[::stride, ::stride].reshape(-1, 3)
        keep = (points[:, 2] > 0) & (np.abs(normals).sum(axis=1) > 0)
        self.points, self.normals = points[keep], normals[keep]
        self.stride, self.kept = stride, keep
        self.target = vertex_map(target_depth, intrinsics)
        self.target_normals = normal_map(self.target, normal_step)
        self.intrinsics = intrinsics

    def pair(self, pose: np.ndarray, gate: float, min_cosine: float) -> _Pairs:
        k, (h, w) = self.intrinsics, self.target.shape[:2]
        moved = self.points @ pose[:3, :3].T + pose[:3, 3]
        z = moved[:, 2]
        safe = np.where(z > 1e-6, z, 1.0)
        u = np.rint(k.fx * moved[:, 0] / safe + k.cx).astype(np.int64)
        v = np.rint(k.fy * moved[:, 1] / safe + k.cy).astype(np.int64)
        inside = (z > 1e-6) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        u, v = np.where(inside, u, 0), np.where(inside, v, 0)
        paired, n = self.target[v, u], self.target_normals[v, u]
        usable = inside & (paired[:, 2] > 0) & (np.abs(n).sum(axis=1) > 0)
        agree = np.sum((self.normals @ pose[:3, :3].T) * n, axis=1) >= min_cosine
        close = np.linalg.norm(moved - paired, axis=1) < gate
        residuals = np.sum(n * (moved - paired), axis=1)
        overlap = float(usable.sum()) / max(len(self.points), 1)
        return _Pairs(moved, n, residuals, usable & agree & close, overlap, u, v)

    def colour_agreement(
        self, found: _Pairs, source_grey: np.ndarray, target_grey: np.ndarray, tolerance: float
    ) -> float:
        """Share of ``found``'s pairs whose grey values agree (ICP result doc)."""
        if not found.pairs.any():
            return 0.0
        s = self.stride
        source = source_grey[::s, ::s].reshape(-1)[self.kept][found.pairs]
        target = target_grey[found.v[found.pairs], found.u[found.pairs]]
        difference = source - target
        difference -= np.median(difference)
        return float(np.mean(np.abs(difference) < tolerance))


def register(
    source_depth: np.ndarray,
    target_depth: np.ndarray,
    intrinsics: Intrinsics,
    initial: np.ndarray,
    settings: IcpSettings = IcpSettings(),
    greys: tuple[np.ndarray, np.ndarray] | None = None,
) -> IcpResult:
    """Register ``source_depth`` to ``target_depth`` (same camera) from ``initial``
    (source camera to target camera); module doc. ``greys``: the (H, W) grey images in
    [0, 1] of source and target, for the colour agreement of the result."""
    step = settings.normal_step or max(1, round(intrinsics.width / 128))
    stride = settings.stride or max(1, round(intrinsics.width / 160))
    images = _Images(source_depth, target_depth, intrinsics, stride, step)
    pose = np.asarray(initial, dtype=np.float64).copy()
    information = np.zeros((6, 6))
    for gate in settings.gates:
        found = images.pair(pose, gate, settings.min_normal_cosine)
        if found.pairs.sum() < 6:
            break
        moved, n, r = (
            found.moved[found.pairs],
            found.normals[found.pairs],
            found.residuals[found.pairs],
        )
        jacobian = np.concatenate([np.cross(moved, n), n], axis=1)
        weights = np.minimum(1.0, settings.huber / np.maximum(np.abs(r), 1e-12))
        information = (jacobian * weights[:, None]).T @ jacobian
        xi = np.linalg.solve(information + 1e-9 * np.eye(6), -(jacobian * weights[:, None]).T @ r)
        pose = _twist_matrix(xi) @ pose
    final = images.pair(pose, settings.inlier_distance, settings.min_normal_cosine)
    count = int(final.pairs.sum())
    residual = float(np.sqrt(np.mean(final.residuals[final.pairs] ** 2))) if count else math.inf
    eigen = float(np.linalg.eigvalsh(information)[0]) / count if count else 0.0
    total = max(round(final.overlap * len(images.points)), 1)
    colour = math.nan
    if greys is not None:
        colour = images.colour_agreement(final, *greys, settings.colour_tolerance)
    return IcpResult(pose, count / total, final.overlap, residual, eigen, colour)
