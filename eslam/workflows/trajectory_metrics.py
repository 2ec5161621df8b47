"""`eslam ate GT EST`: the trajectory errors of two trajectory files (docs/evaluation.md).

Reads both trajectories (TUM files, Replica ``traj.txt`` files or run folders, as
:func:`eslam.io.trajectory.read_trajectory` reads them; missing poses allowed), matches
them by timestamp and measures the ATE after alignment and, where two consecutive
matched poses exist, the RPE (:mod:`eslam.evaluate.trajectory`). The CLI prints the
result; this module computes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from eslam.errors import ConfigError, InputError
from eslam.evaluate.trajectory import (
    ATEResult,
    RPEResult,
    TimedPoses,
    trajectory_ate,
    trajectory_rpe,
)
from eslam.io.trajectory import read_trajectory

ALIGNMENTS = ("se3", "sim3")
"""How the estimate is aligned onto the ground truth: rigid (the paper's) or similarity."""


@dataclass(frozen=True)
class TrajectoryErrors:
    """The errors of an estimated trajectory against the ground truth.

    Attributes:
        ate: the absolute trajectory error after alignment.
        rpe: the relative pose error over consecutive matched poses (None when no two
            consecutive matched poses are finite).
        align: the alignment used, one of :data:`ALIGNMENTS`.
        max_diff: the largest timestamp difference of a matched pair, seconds.
    """

    ate: ATEResult
    rpe: RPEResult | None
    align: str
    max_diff: float

    def as_dict(self) -> dict[str, object]:
        """The ATE statistics (cm), ``align``, ``max_diff_s``, then the RPE's (mm, deg)."""
        metrics: dict[str, object] = {
            **self.ate.as_dict(),
            "align": self.align,
            "max_diff_s": self.max_diff,
        }
        if self.rpe is not None:
            metrics.update(self.rpe.as_dict())
        return metrics


def trajectory_errors(
    gt_path: str | Path, est_path: str | Path, align: str = "se3", max_diff: float = 0.01
) -> TrajectoryErrors:
    """ATE (and RPE) of the trajectory in ``est_path`` against the one in ``gt_path``.

    Args:
        gt_path: ground-truth trajectory file, or a run folder (its trajectory_gt.txt).
        est_path: estimated trajectory file, or a run folder (its trajectory.txt).
        align: ``se3`` (rigid, the paper's) or ``sim3`` (with scale).
        max_diff: largest timestamp difference of a matched pair, seconds.

    Raises:
        InputError: a file is missing or unreadable, or fewer than 3 poses match
            (named as the estimate's problem).
        ConfigError: an unknown ``align``.
    """
    if align not in ALIGNMENTS:
        raise ConfigError(f"unknown alignment {align!r} (choose {' or '.join(ALIGNMENTS)})")
    gt = TimedPoses(*read_trajectory(gt_path, ground_truth=True, allow_missing=True))
    est = TimedPoses(*read_trajectory(est_path, allow_missing=True))
    try:
        ate = trajectory_ate(gt, est, align == "sim3", max_diff)
    except ValueError as error:
        raise InputError(
            est_path, str(error), "check that both files cover the same frames, or --max-diff"
        ) from None
    try:  # relative motions need no alignment; a pair needs two consecutive matched poses
        rpe = trajectory_rpe(gt, est, 1, max_diff)
    except ValueError:
        rpe = None  # no consecutive finite pair: the ATE stands alone
    return TrajectoryErrors(ate, rpe, align, max_diff)
