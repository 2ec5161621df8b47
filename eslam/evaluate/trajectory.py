"""Absolute trajectory error (ATE) after Umeyama alignment (docs/method.md section 6), and
the relative pose error (RPE) between consecutive poses."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Alignment:
    """x_aligned = scale * rotation @ x + translation."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Align (N, 3) points."""
        return self.scale * points @ self.rotation.T + self.translation


@dataclass(frozen=True)
class ATEResult:
    """ATE statistics in metres over ``pairs`` matched positions.

    Attributes:
        rmse, mean, median, max: of the position errors after alignment, metres.
        pairs: matched poses used.
        alignment: the transform applied to the estimate.
        errors: (pairs,) position errors, metres.
        excluded: matched pairs left out because a pose was not finite (missing).
    """

    rmse: float
    mean: float
    median: float
    max: float
    pairs: int
    alignment: Alignment
    errors: np.ndarray
    excluded: int = 0

    def as_cm(self) -> dict[str, float]:
        """The statistics in centimetres, with the keys metrics.json uses."""
        return {"ate_rmse_cm": 100 * self.rmse, "ate_mean_cm": 100 * self.mean}

    def as_dict(self) -> dict[str, float | int]:
        """Every statistic (centimetres), the pair counts and the alignment scale."""
        return {
            "ate_rmse_cm": 100 * self.rmse,
            "ate_mean_cm": 100 * self.mean,
            "ate_median_cm": 100 * self.median,
            "ate_max_cm": 100 * self.max,
            "pairs": self.pairs,
            "excluded": self.excluded,
            "scale": self.alignment.scale,
        }


def umeyama_alignment(
    source: np.ndarray, target: np.ndarray, with_scale: bool = False
) -> Alignment:
    """Least-squares similarity (or rigid) transform taking ``source`` onto ``target``.

    Umeyama, "Least-squares estimation of transformation parameters between two point
    patterns", TPAMI 1991: with centred point sets X (source) and Y (target) and the SVD
    of the cross-covariance Sigma = Y^T X / n = U D V^T, R = U S V^T (S fixes a reflection),
    c = trace(D S) / var(X) (1 without scale), t = mean(Y) - c R mean(X).

    Args:
        source: (N, 3) estimated positions.
        target: (N, 3) ground-truth positions.
    """
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(f"need two (N, 3) arrays, got {source.shape} and {target.shape}")
    if len(source) < 3:
        raise ValueError(f"need at least 3 positions to align, got {len(source)}")
    mean_source, mean_target = source.mean(axis=0), target.mean(axis=0)
    centred_source, centred_target = source - mean_source, target - mean_target
    covariance = centred_target.T @ centred_source / len(source)
    u, d, vt = np.linalg.svd(covariance)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1.0
    rotation = u @ s @ vt
    scale = 1.0
    if with_scale:
        variance = (centred_source**2).sum() / len(source)
        scale = float(np.trace(np.diag(d) @ s) / variance)
    translation = mean_target - scale * rotation @ mean_source
    return Alignment(rotation=rotation, translation=translation, scale=scale)


def absolute_trajectory_error(
    estimated: np.ndarray, ground_truth: np.ndarray, with_scale: bool = False
) -> ATEResult:
    """ATE of camera positions after aligning ``estimated`` onto ``ground_truth``.

    Args:
        estimated: (N, 3) positions or (N, 4, 4) camera-to-world poses.
        ground_truth: the same shape, matched row by row. Rows where either is not
            finite are left out (e.g. ScanNet's invalid poses) and counted in
            ``excluded``.
        with_scale: Sim(3) alignment (also fit a scale) instead of SE(3).

    Raises:
        ValueError: fewer than 3 usable pairs.
    """
    estimated = np.asarray(estimated, dtype=np.float64)
    ground_truth = np.asarray(ground_truth, dtype=np.float64)
    est = estimated[:, :3, 3] if estimated.ndim == 3 else estimated
    gt = ground_truth[:, :3, 3] if ground_truth.ndim == 3 else ground_truth
    if estimated.ndim == 3:
        est = np.where(np.isfinite(estimated).all(axis=(1, 2))[:, None], est, np.nan)
    if ground_truth.ndim == 3:
        gt = np.where(np.isfinite(ground_truth).all(axis=(1, 2))[:, None], gt, np.nan)
    keep = np.isfinite(est).all(axis=1) & np.isfinite(gt).all(axis=1)
    est, gt = est[keep].astype(np.float64), gt[keep].astype(np.float64)
    alignment = umeyama_alignment(est, gt, with_scale)
    errors = np.linalg.norm(alignment.apply(est) - gt, axis=1)
    return ATEResult(
        rmse=float(np.sqrt(np.mean(errors**2))),
        mean=float(errors.mean()),
        median=float(np.median(errors)),
        max=float(errors.max()),
        pairs=len(errors),
        alignment=alignment,
        errors=errors,
        excluded=int(np.count_nonzero(~keep)),
    )


@dataclass(frozen=True)
class RPEResult:
    """Relative pose error over ``pairs`` pose pairs ``delta`` frames apart.

    Attributes:
        translation_rmse, translation_median: of |trans(E_i)|, metres.
        rotation_rmse, rotation_median: of angle(rot(E_i)), degrees.
        pairs: pose pairs used (both poses of a pair finite in both trajectories).
        delta: frames between the two poses of a pair.
    """

    translation_rmse: float
    translation_median: float
    rotation_rmse: float
    rotation_median: float
    pairs: int
    delta: int

    def as_dict(self) -> dict[str, float | int]:
        """The statistics in millimetres and degrees, with the pair count."""
        return {
            "rpe_translation_rmse_mm": 1000 * self.translation_rmse,
            "rpe_translation_median_mm": 1000 * self.translation_median,
            "rpe_rotation_rmse_deg": self.rotation_rmse,
            "rpe_rotation_median_deg": self.rotation_median,
            "rpe_pairs": self.pairs,
        }


@dataclass(frozen=True, eq=False)
class PairErrors:
    """The relative pose error of each pose pair (:func:`pair_errors`).

    Attributes:
        first: (M,) index of each pair's first pose (the second is ``first + delta``).
        translation: (M,) |trans(E_i)|, metres.
        rotation: (M,) angle(rot(E_i)), degrees.
    """

    first: np.ndarray
    translation: np.ndarray
    rotation: np.ndarray


def pair_errors(estimated: np.ndarray, ground_truth: np.ndarray, delta: int = 1) -> PairErrors:
    """Each pair's relative pose error, as Sturm et al. (IROS 2012, the TUM RGB-D
    benchmark) define it and evo's ``evo_rpe --delta 1 --delta_unit f`` computes it:

        E_i = (Q_i^-1 Q_{i+delta})^-1 (P_i^-1 P_{i+delta})

    with Q the ground truth and P the estimate, matched row by row; the translation
    error is |trans(E_i)| and the rotation error the angle of rot(E_i),
    arccos((trace(R) - 1) / 2).

    Args:
        estimated, ground_truth: (N, 4, 4) camera-to-world poses. A pair with a
            non-finite pose in either trajectory is left out.
        delta: frames between the two poses of a pair (>= 1).

    Raises:
        ValueError: shapes differ, delta < 1, or no usable pair.
    """
    estimated = np.asarray(estimated, dtype=np.float64)
    ground_truth = np.asarray(ground_truth, dtype=np.float64)
    if estimated.shape != ground_truth.shape or estimated.shape[1:] != (4, 4):
        raise ValueError(
            f"need two (N, 4, 4) pose arrays, got {estimated.shape} and {ground_truth.shape}"
        )
    if delta < 1:
        raise ValueError(f"delta must be at least 1 frame, got {delta}")
    finite = np.isfinite(estimated).all(axis=(1, 2)) & np.isfinite(ground_truth).all(axis=(1, 2))
    first = np.flatnonzero(finite[:-delta] & finite[delta:]) if len(finite) > delta else []
    if len(first) == 0:
        raise ValueError(f"no pair of finite poses {delta} frame(s) apart")
    second = first + delta
    motion_gt = np.linalg.inv(ground_truth[first]) @ ground_truth[second]
    motion_est = np.linalg.inv(estimated[first]) @ estimated[second]
    error = np.linalg.inv(motion_gt) @ motion_est
    cosine = (np.trace(error[:, :3, :3], axis1=1, axis2=2) - 1.0) / 2.0
    return PairErrors(
        first=np.asarray(first),
        translation=np.linalg.norm(error[:, :3, 3], axis=1),
        rotation=np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))),
    )


def relative_pose_error(
    estimated: np.ndarray, ground_truth: np.ndarray, delta: int = 1
) -> RPEResult:
    """RPE statistics over the pairs of :func:`pair_errors` (same arguments and errors).
    Needs no alignment (relative motions do not depend on the world frame), so it
    measures the per-frame tracking error (jitter and local drift) that the ATE mixes
    with the drift accumulated over the whole run."""
    pairs = pair_errors(estimated, ground_truth, delta)
    translation, rotation = pairs.translation, pairs.rotation
    return RPEResult(
        translation_rmse=float(np.sqrt(np.mean(translation**2))),
        translation_median=float(np.median(translation)),
        rotation_rmse=float(np.sqrt(np.mean(rotation**2))),
        rotation_median=float(np.median(rotation)),
        pairs=len(pairs.first),
        delta=delta,
    )


@dataclass(frozen=True, eq=False)
class TimedPoses:
    """A trajectory: camera-to-world poses with their timestamps.

    Attributes:
        timestamps: (N,) float64 seconds (or frame indices).
        poses: (N, 4, 4) float64 camera-to-world; all-NaN rows are missing poses.
    """

    timestamps: np.ndarray
    poses: np.ndarray


def trajectory_ate(
    ground_truth: TimedPoses,
    estimate: TimedPoses,
    with_scale: bool = False,
    max_difference: float = 0.01,
) -> ATEResult:
    """ATE of two timestamped trajectories, as evo's ``evo_ape tum GT EST -a`` computes it.

    Poses are matched by :func:`associate_timestamps` (within ``max_difference``
    seconds; evo's default is 0.01), pairs with a missing (non-finite) pose are left
    out, then :func:`absolute_trajectory_error` aligns and measures the positions.

    Raises:
        ValueError: fewer than 3 usable pairs (the message says how many matched).
    """
    est_index, gt_index = associate_timestamps(
        estimate.timestamps, ground_truth.timestamps, max_difference
    )
    matched = len(est_index)
    est = estimate.poses[est_index]
    gt = ground_truth.poses[gt_index]
    usable = int(
        np.count_nonzero(np.isfinite(est).all(axis=(1, 2)) & np.isfinite(gt).all(axis=(1, 2)))
    )
    if usable < 3:
        raise ValueError(
            f"only {matched} poses matched within {max_difference} s and {usable} of them "
            "have finite poses; need at least 3"
        )
    return absolute_trajectory_error(est, gt, with_scale)


def trajectory_rpe(
    ground_truth: TimedPoses, estimate: TimedPoses, delta: int = 1, max_difference: float = 0.01
) -> RPEResult:
    """RPE of two timestamped trajectories, as evo's ``evo_rpe tum GT EST --delta 1
    --delta_unit f`` computes it: poses matched by :func:`associate_timestamps`, then
    :func:`relative_pose_error` over pairs ``delta`` matched poses apart."""
    est_index, gt_index = associate_timestamps(
        estimate.timestamps, ground_truth.timestamps, max_difference
    )
    return relative_pose_error(estimate.poses[est_index], ground_truth.poses[gt_index], delta)


def associate_timestamps(
    first: np.ndarray, second: np.ndarray, max_difference: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Match two sorted timestamp lists one-to-one, nearest first (TUM's associate.py rule).

    Candidate pairs closer than ``max_difference`` seconds are taken in order of
    increasing time difference, each timestamp used at most once.

    Returns:
        Index arrays (into ``first`` and ``second``) of the matched pairs, sorted by ``first``.
    """
    order = np.argsort(second)
    sorted_second = second[order]
    candidates = []
    for i, t in enumerate(first):
        lo = np.searchsorted(sorted_second, t - max_difference, side="left")
        hi = np.searchsorted(sorted_second, t + max_difference, side="right")
        for j in range(lo, hi):
            difference = abs(sorted_second[j] - t)
            if difference < max_difference:
                candidates.append((difference, i, int(order[j])))
    candidates.sort()
    used_first: set[int] = set()
    used_second: set[int] = set()
    pairs = []
    for _, i, j in candidates:
        if i not in used_first and j not in used_second:
            used_first.add(i)
            used_second.add(j)
            pairs.append((i, j))
    pairs.sort()
    if not pairs:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    index = np.array(pairs, dtype=np.int64)
    return index[:, 0], index[:, 1]
