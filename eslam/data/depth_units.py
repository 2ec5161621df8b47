"""Is a frame's depth in metres? The depth-unit checks of readers, runs and ``eslam inspect``.

Two levels, because a wrong ``data.depth_scale`` (or depth files written in another
unit) never fails loudly on its own: it only makes the map worse, or 9x slower and
larger (issue 15).

- :func:`check_depth_units` (every frame a reader returns): the median valid depth must
  lie in :data:`DEPTH_MEDIAN_RANGE_M`; outside it no indoor sensor could have measured it.
- :class:`DepthCheck` (a run's first and last frames and every keyframe, and every
  frame ``eslam inspect`` reads): the median and the far end of the depth (95th
  percentile) against what indoor RGB-D sensors see (:data:`PLAUSIBLE_MEDIAN_M`,
  :data:`PLAUSIBLE_FAR_M`) and against a configured scene bound. This catches depth
  divided by 10, and a scale off by 5x or more in most scenes; the ranges leave a
  factor of 2.7 or more around every real and synthetic sequence measured.

Both name the frame, the setting (``data.depth_scale``) and the scales that would make
the depth plausible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.errors import InputError

DEPTH_MEDIAN_RANGE_M = (0.1, 20.0)
"""A frame's median valid depth must lie in this range (metres) after scaling, or the
depth scale is wrong: no indoor RGB-D sensor we read sees a median closer or farther."""

COMMON_DEPTH_SCALES = (1.0, 1000.0, 5000.0, 6553.5)
"""Depth PNG units per metre of the usual layouts (metres, ScanNet/7-Scenes mm, TUM, Replica)."""

PLAUSIBLE_MEDIAN_M = (0.35, 8.0)
"""Range of a frame's median valid depth (metres) that SLAM with an indoor RGB-D sensor
sees. Measured: 7-Scenes redkitchen 1.2-2.4 m, Replica room0 2.7-2.9 m, office0 2.0 m,
``eslam synth`` rooms 2.0-2.5 m; depth divided by 10 gives 0.12-0.29 m."""

PLAUSIBLE_FAR_M = (0.7, 12.0)
"""Range of a frame's far end (95th percentile of valid depth, metres). Below 0.7 m the
whole view would be within arm's length (Kinect v1 and v2 measure nothing closer than
0.4-0.5 m); above 12 m it is beyond every indoor sensor's range (Kinect v1/v2 and Azure
Kinect stop at 4-8 m, RealSense D4xx at about 10 m). Measured far ends: 2.4-4.4 m on the
sequences above; a scale 5x too small gives 0.49-0.88 m (Replica room0's 0.85 m passes),
5x too large 12-22 m."""

TYPICAL_MEDIAN_M = 2.0
"""The median depth suggestions aim at: the middle of the measured range above."""

FAR_PERCENTILE = 95.0
"""Percentile of valid depth taken as a frame's far end (robust to a few far outliers)."""

SPREAD_SAMPLES = 20_000
"""Valid pixels (evenly strided) a spread is computed from: keeps a keyframe's check
at about a millisecond at 1200x680."""


@dataclass(frozen=True)
class DepthSpread:
    """Where a frame's valid depth lies.

    Attributes:
        median_m: median valid depth, metres.
        far_m: the far end, the :data:`FAR_PERCENTILE` percentile of valid depth, metres.
    """

    median_m: float
    far_m: float

    @classmethod
    def of(cls, depth: np.ndarray) -> DepthSpread | None:
        """The spread of (H, W) depth in metres (0 = invalid), or None without valid depth."""
        valid = depth[np.isfinite(depth) & (depth > 0)]
        if valid.size == 0:
            return None
        if valid.size > SPREAD_SAMPLES:  # an even stride: the percentiles barely move
            valid = valid[:: valid.size // SPREAD_SAMPLES]
        median, far = np.percentile(valid, [50.0, FAR_PERCENTILE])
        return cls(float(median), float(far))

    def scaled(self, factor: float) -> DepthSpread:
        """The spread of the same depth multiplied by ``factor``."""
        return DepthSpread(self.median_m * factor, self.far_m * factor)


def implausibility(spread: DepthSpread, bound_diagonal: float | None = None) -> str | None:
    """Why ``spread`` cannot be metres seen by an indoor RGB-D sensor, or None if it can.

    Args:
        spread: a frame's depth spread, metres as read.
        bound_diagonal: the diagonal of a configured scene bound (metres): the camera is
            inside the bound, so half its points cannot lie farther than this.
    """
    low, high = PLAUSIBLE_MEDIAN_M
    near, far = PLAUSIBLE_FAR_M
    if spread.median_m < low:
        return f"closer than the {low:g} m an indoor RGB-D sensor's median depth reaches"
    if spread.far_m < near:
        return f"the whole view within {near:g} m: closer than indoor RGB-D SLAM works"
    if spread.median_m > high:
        return f"farther than the {high:g} m an indoor RGB-D sensor's median depth reaches"
    if spread.far_m > far:
        return f"the far end beyond the {far:g} m an indoor RGB-D sensor measures"
    if bound_diagonal is not None and spread.median_m > bound_diagonal:
        return f"farther than the scene bound's diagonal ({bound_diagonal:.2f} m)"
    return None


def _fits(spread: DepthSpread, bound_diagonal: float | None) -> bool:
    return implausibility(spread, bound_diagonal) is None


def suggested_factors(
    spread: DepthSpread, depth_scale: float | None = None, bound_diagonal: float | None = None
) -> list[float]:
    """Factors (up to two) to multiply the depth by that would make ``spread`` plausible,
    the likeliest first.

    Candidates: the factors that turn ``depth_scale`` (when known) into one of the usual
    layouts' scales (:data:`COMMON_DEPTH_SCALES`), tried first, then the ratios between
    those scales (6.5535 between Replica and millimetres, 5 between TUM and millimetres)
    and powers of ten (depth written in cm, dm ...). Within each group, those that make
    the depth plausible are ordered by how close they bring the median to
    :data:`TYPICAL_MEDIAN_M`.
    """
    usual = set() if depth_scale is None else {depth_scale / c for c in COMMON_DEPTH_SCALES}
    ratios = {a / b for a in COMMON_DEPTH_SCALES for b in COMMON_DEPTH_SCALES if a != b}
    ratios |= {10.0**k for k in range(-4, 5) if k}

    def rank(factor: float) -> tuple[bool, float]:
        closeness = abs(math.log(spread.median_m * factor / TYPICAL_MEDIAN_M))
        return factor not in usual, closeness

    fitting = [f for f in usual | ratios if _fits(spread.scaled(f), bound_diagonal)]
    return sorted(fitting, key=rank)[:2]


def _scale_text(scale: float) -> str:
    return f"{scale:.6g}"


@dataclass(frozen=True)
class DepthCheck:
    """The run's depth-unit check (module doc), with what it needs to explain itself.

    Attributes:
        enabled: whether to check at all (a caller's choice; runs always check).
        depth_scale: the depth files' units per metre as read (the sequence's, from
            ``data.depth_scale`` or the layout's default); None when unknown (a live
            source): the suggestion is then a factor.
        bound_diagonal: diagonal of ``scene.bound`` when set (metres), else None.
    """

    enabled: bool = True
    depth_scale: float | None = None
    bound_diagonal: float | None = None

    @classmethod
    def for_run(
        cls,
        depth_scale: float | None,
        bound: list[list[float]] | None,
        enabled: bool = True,
    ) -> DepthCheck:
        """The check of a run reading depth with ``depth_scale``, in ``scene.bound`` (or
        None); ``enabled`` is ``data.depth_check``."""
        diagonal = None
        if bound is not None:
            diagonal = float(np.linalg.norm([high - low for low, high in bound]))
        return cls(enabled, depth_scale, diagonal)

    def problem(self, depth: np.ndarray, where: str | Path, frame: str) -> InputError | None:
        """The error to raise for a frame's (H, W) depth in metres, or None if plausible.

        Args:
            depth: the frame's depth as read (metres, 0 = invalid).
            where: the depth file, or the sequence or stream the frame came from.
            frame: names the frame in the message ("frame 12 (timestamp 0.4)").
        """
        if not self.enabled:
            return None
        spread = DepthSpread.of(depth)
        if spread is None:
            return None
        reason = implausibility(spread, self.bound_diagonal)
        if reason is None:
            return None
        problem = (
            f"{frame}: median depth {spread.median_m:.3g} m, far end {spread.far_m:.3g} m: "
            f"{reason}, so the depth is not in metres"
        )
        return InputError(where, problem, self._fix(spread))

    def check(self, depth: np.ndarray, where: str | Path, frame: str) -> None:
        """Raise :meth:`problem`'s InputError, if any."""
        error = self.problem(depth, where, frame)
        if error is not None:
            raise error

    def _fix(self, spread: DepthSpread) -> str:
        factors = suggested_factors(spread, self.depth_scale, self.bound_diagonal)
        if not factors:
            return (
                "check data.depth_scale and the unit of the depth files "
                "(data.depth_check=false if this depth is right)"
            )
        if self.depth_scale is None:
            options = " or ".join(f"{f:.4g}x (median {spread.median_m * f:.2f} m)" for f in factors)
            return (
                f"the depth looks off by a factor of {options}: fix its unit "
                "(data.depth_check=false if this depth is right)"
            )
        options = " or ".join(
            f"data.depth_scale={_scale_text(self.depth_scale / f)} "
            f"(median {spread.median_m * f:.2f} m)"
            for f in factors
        )
        now = _scale_text(self.depth_scale)
        return f"likely {options} instead of {now} (data.depth_check=false if this depth is right)"


def sequence_depth_scale(sequence: object) -> float | None:
    """The units per metre a recorded sequence reads its depth files with, or None.

    File readers keep it on their :class:`~eslam.data.base.FrameReading`; a frame
    selection wraps its sequence (``.sequence``).
    """
    while not hasattr(sequence, "reading") and hasattr(sequence, "sequence"):
        sequence = sequence.sequence
    reading = getattr(sequence, "reading", None)
    scale = getattr(reading, "depth_scale", None)
    return float(scale) if scale is not None else None


def sequence_depth_file(sequence: object, index: int) -> Path | None:
    """The depth file of frame ``index`` of a recorded sequence, where the reader says."""
    while hasattr(sequence, "positions") and hasattr(sequence, "sequence"):
        index = sequence.positions[index]
        sequence = sequence.sequence
    locate = getattr(sequence, "depth_path", None)
    return locate(index) if locate is not None else None


def check_depth_units(depth: np.ndarray, path: Path, depth_scale: float) -> None:
    """Raise if the valid depth of a frame cannot be in metres (the scale is wrong).

    The reader's check of every frame: only a median outside :data:`DEPTH_MEDIAN_RANGE_M`,
    which no sensor produces (:class:`DepthCheck` judges what is merely implausible).
    A frame with no valid depth passes (it is skipped by the run loop, with a warning).

    Args:
        depth: (H, W) depth in metres as read with ``depth_scale`` (0 = invalid).
        path: the depth image, named in the error.
        depth_scale: the units per metre used to read it.
    """
    valid = depth[depth > 0]
    if valid.size == 0:
        return
    median = float(np.median(valid))
    low, high = DEPTH_MEDIAN_RANGE_M
    if low <= median <= high:
        return
    raw_median = median * depth_scale
    fitting = [s for s in COMMON_DEPTH_SCALES if low <= raw_median / s <= high]
    if fitting:
        best = min(fitting, key=lambda s: abs(np.log(raw_median / s / 2.0)))
        suggestion = f"depth scale {best:g} would give {raw_median / best:.2f} m"
    else:
        suggestion = f"a depth scale near {raw_median / 2.0:.4g} would give about 2 m"
    raise InputError(
        path,
        f"median depth is {median:.4g} m with depth scale {depth_scale:g} units per metre, "
        f"outside {low:g}-{high:g} m: the depth scale is wrong",
        f"{suggestion}; set data.depth_scale",
    )
