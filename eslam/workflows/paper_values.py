"""The paper's published numbers that ``eslam table`` shows beside a sweep's.

Transcribed from the ESLAM supplementary material (Johari et al., CVPR 2023;
/work/shared/spec/ESLAM-supplementary.txt), ESLAM's own rows only:

- Tab. 1 (depth resolution, Replica room0): ATE RMSE, accuracy, completion at full
  depth ("1 D") and depth downsampled to 1/8 ("1/8 D");
- Tab. 3 (ablations a-h and i, the full model): ScanNet ATE RMSE; Replica ATE RMSE,
  accuracy, completion (averages over each dataset's scenes);
- Tab. 4 (per Replica scene, mean +- std of five runs): depth L1, accuracy, completion,
  completion ratio, ATE mean, ATE RMSE, and their average over the 8 scenes;
- Tab. 5 (iterations, Replica average): accuracy, completion, ATE RMSE, FPT (RTX 3090)
  of ESLAM (15 mapping / 8 tracking iterations), x2 (30 / 16) and x10 (150 / 80).

Scenes are named ``replica`` (the average over Replica's 8 scenes), ``replica/room0``
... ``replica/office4`` and ``scannet`` (the average over ScanNet's scenes);
experiments ``full``, ``a`` ... ``h``, ``x2``, ``x10`` and ``depth/8``. Metric keys are
metrics.json's. Where two tables report the same number (Tab. 3's i, Tab. 4's average
and Tab. 5's ESLAM row agree), the first of Tab. 4, 1, 3, 5 that has it is shown.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PaperValue:
    """One published number.

    Attributes:
        scene: ``replica``, ``replica/<scene>`` or ``scannet``.
        experiment: ``full``, ``a``-``h``, ``x2``, ``x10`` or ``depth/8``.
        metric: the metrics.json key (``ate_rmse_cm`` ...).
        value: the number as printed.
        std: its standard deviation over five runs where printed (Tab. 4), else None.
        source: the table, row and column it was read from.
    """

    scene: str
    experiment: str
    metric: str
    value: float
    std: float | None
    source: str


TABLE4_METRICS = (
    ("depth_l1_cm", "Depth L1"),
    ("accuracy_cm", "Acc."),
    ("completion_cm", "Comp."),
    ("completion_ratio_pct", "Comp. Ratio"),
    ("ate_mean_cm", "ATE Mean"),
    ("ate_rmse_cm", "ATE RMSE"),
)
"""Tab. 4's columns, left to right."""

TABLE4_ESLAM = """
room0    0.97 ± 0.04  1.07 ± 0.01  1.12 ± 0.01  99.06 ± 0.05  0.61 ± 0.06  0.71 ± 0.13
room1    1.07 ± 0.07  0.85 ± 0.01  0.88 ± 0.01  99.64 ± 0.06  0.56 ± 0.02  0.70 ± 0.02
room2    1.28 ± 0.07  0.93 ± 0.01  1.05 ± 0.01  98.84 ± 0.06  0.43 ± 0.01  0.52 ± 0.01
office0  0.86 ± 0.02  0.85 ± 0.01  0.96 ± 0.01  98.34 ± 0.05  0.42 ± 0.03  0.57 ± 0.04
office1  1.26 ± 0.02  0.83 ± 0.06  0.81 ± 0.01  98.85 ± 0.08  0.46 ± 0.05  0.55 ± 0.04
office2  1.71 ± 0.07  1.02 ± 0.01  1.09 ± 0.01  98.60 ± 0.12  0.47 ± 0.03  0.58 ± 0.09
office3  1.43 ± 0.05  1.21 ± 0.01  1.42 ± 0.01  96.80 ± 0.03  0.61 ± 0.03  0.72 ± 0.02
office4  1.06 ± 0.08  1.15 ± 0.02  1.27 ± 0.01  97.65 ± 0.14  0.52 ± 0.02  0.63 ± 0.03
Average  1.18 ± 0.05  0.97 ± 0.02  1.05 ± 0.01  98.60 ± 0.07  0.52 ± 0.03  0.63 ± 0.05
"""
"""Tab. 4, rows "ESLAM (Ours)" as printed: a scene, then mean ± std per column of
TABLE4_METRICS."""

TABLE1_ESLAM = {"full": ("1 D", 0.71, 1.07, 1.12), "depth/8": ("1/8 D", 0.72, 1.16, 1.23)}
"""Tab. 1, rows "ESLAM (ours)" on Replica room0: (row, ATE, Acc., Comp.)."""

TABLE3_ROWS = {
    "a": (7.49, 0.65, 0.99, 1.08),
    "b": (7.53, 0.97, 1.12, 1.29),
    "c": (8.27, 0.72, 1.00, 1.09),
    "d": (7.55, 0.64, 0.98, 1.07),
    "e": (7.44, 0.67, 1.08, 1.14),
    "f": (8.31, 0.68, 1.03, 1.08),
    "g": (8.28, 0.71, 1.01, 1.10),
    "h": (11.27, 4.85, 2.23, 2.21),
    "full": (7.38, 0.63, 0.97, 1.05),
}
"""Tab. 3: ScanNet ATE, Replica ATE, Accuracy, Completion per row (i = ``full``)."""

TABLE5_ROWS = {
    "full": ("ESLAM", 0.97, 1.05, 0.63, 0.18),
    "x2": ("ESLAM x2", 0.95, 1.03, 0.42, 0.35),
    "x10": ("ESLAM x10", 0.92, 1.01, 0.31, 1.72),
}
"""Tab. 5 (Replica average): (row, Acc., Comp., ATE, FPT s)."""


def _table4() -> list[PaperValue]:
    values = []
    for line in TABLE4_ESLAM.strip().splitlines():
        row, *numbers = line.replace("±", " ").split()
        pairs = [(float(a), float(b)) for a, b in zip(numbers[::2], numbers[1::2], strict=True)]
        scene = "replica" if row == "Average" else f"replica/{row}"
        for (metric, column), (value, std) in zip(TABLE4_METRICS, pairs, strict=True):
            source = f"suppl. Tab. 4, {row}, ESLAM, {column}"
            values.append(PaperValue(scene, "full", metric, value, std, source))
    return values


def _table1() -> list[PaperValue]:
    values = []
    metrics = (("ate_rmse_cm", "ATE"), ("accuracy_cm", "Acc."), ("completion_cm", "Comp."))
    for experiment, (row, *numbers) in TABLE1_ESLAM.items():
        for (metric, column), value in zip(metrics, numbers, strict=True):
            source = f"suppl. Tab. 1, {row}, ESLAM, {column}"
            values.append(PaperValue("replica/room0", experiment, metric, value, None, source))
    return values


def _table3() -> list[PaperValue]:
    values = []
    columns = (
        ("scannet", "ate_rmse_cm", "ScanNet ATE"),
        ("replica", "ate_rmse_cm", "Replica ATE"),
        ("replica", "accuracy_cm", "Replica Accuracy"),
        ("replica", "completion_cm", "Replica Completion"),
    )
    for experiment, numbers in TABLE3_ROWS.items():
        row = "i" if experiment == "full" else experiment
        for (scene, metric, column), value in zip(columns, numbers, strict=True):
            source = f"suppl. Tab. 3, row {row}, {column}"
            values.append(PaperValue(scene, experiment, metric, value, None, source))
    return values


def _table5() -> list[PaperValue]:
    values = []
    metrics = (
        ("accuracy_cm", "Acc."),
        ("completion_cm", "Comp."),
        ("ate_rmse_cm", "ATE"),
        ("fpt_s", "FPT"),
    )
    for experiment, (row, *numbers) in TABLE5_ROWS.items():
        for (metric, column), value in zip(metrics, numbers, strict=True):
            source = f"suppl. Tab. 5, {row}, {column}"
            values.append(PaperValue("replica", experiment, metric, value, None, source))
    return values


PAPER_VALUES: tuple[PaperValue, ...] = (*_table4(), *_table1(), *_table3(), *_table5())
"""Every transcribed number, in the order lookups prefer them (Tab. 4, 1, 3, 5)."""

PAPER_SCENES = tuple(dict.fromkeys(value.scene for value in PAPER_VALUES))
"""Scene names a sweep's ``paper`` may take."""
PAPER_EXPERIMENTS = tuple(dict.fromkeys(value.experiment for value in PAPER_VALUES))
"""Experiment names a variant's ``paper`` may take."""


def paper_value(scene: str, experiment: str, metric: str) -> PaperValue | None:
    """The published number of ``metric`` for ``experiment`` on ``scene``, or None."""
    for value in PAPER_VALUES:
        if (value.scene, value.experiment, value.metric) == (scene, experiment, metric):
            return value
    return None
