"""`eslam table DIR`: a sweep's finished cells as the paper's tables.

Per dataset and variant, the mean +- std over seeds of every metric of TABLE_METRICS
that the cells' metrics.json hold, with the paper's number beside it where the cell
repeats one of the paper's experiments (cell.json's paper_scene / paper_experiment;
:mod:`eslam.workflows.paper_values`). Writes DIR/table.md, DIR/table.csv,
DIR/table.json (a list of rows ``{"dataset", "variant", "metric", "mean", "std", "n",
"paper", "paper_std", "paper_source"}``) and one bar plot per metric
(DIR/plots/<metric>.png, the ``[viz]`` extra).

std is the sample standard deviation over seeds (n - 1 in the denominator;
null for a single seed); the paper does not say which it reports.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from eslam.atomic import write_text
from eslam.errors import InputError
from eslam.io.run_dir import json_text
from eslam.viz.sweep_plots import plot_metric_bars
from eslam.workflows.paper_values import paper_value
from eslam.workflows.sweep_cells import CELL_FILE, SWEEP_FILE

TABLE_METRICS = (
    ("ate_rmse_cm", "ATE RMSE (cm)"),
    ("ate_mean_cm", "ATE mean (cm)"),
    ("accuracy_cm", "Acc. (cm)"),
    ("completion_cm", "Comp. (cm)"),
    ("completion_ratio_pct", "Comp. ratio (%)"),
    ("depth_l1_cm", "Depth L1 (cm)"),
    ("f1_pct", "F1 (%)"),
    ("fpt_s", "FPT (s)"),
)
"""metrics.json keys a table reports, in the paper's order, with their column titles."""

ROW_KEYS = (
    "dataset",
    "variant",
    "metric",
    "mean",
    "std",
    "n",
    "paper",
    "paper_std",
    "paper_source",
)
"""Fields of every row of table.json and columns of table.csv."""


@dataclass(frozen=True)
class CellResult:
    """A finished cell's metrics.

    Attributes:
        dataset, variant, seed: where in the grid.
        metrics: its metrics.json.
        paper_scene, paper_experiment: what of the paper it repeats (or None).
    """

    dataset: str
    variant: str
    seed: int
    metrics: dict
    paper_scene: str | None = None
    paper_experiment: str | None = None


@dataclass(frozen=True)
class SweepCells:
    """The cells found under a sweep's output folder.

    Attributes:
        finished: cells whose cell.json says done, with their metrics.
        unfinished: ``dataset/variant/seed<k>: status (error)`` of every other cell.
    """

    finished: tuple[CellResult, ...]
    unfinished: tuple[str, ...]


@dataclass(frozen=True)
class TableResult:
    """What ``eslam table`` wrote.

    Attributes:
        rows: table.json's rows.
        files: the files written (table.md, table.csv, table.json, plots).
        unfinished: cells left out (see :class:`SweepCells`).
    """

    rows: tuple[dict, ...]
    files: tuple[Path, ...]
    unfinished: tuple[str, ...]


def collect_cells(out: str | Path) -> SweepCells:
    """Every cell (``OUT/<dataset>/<variant>/seed<k>/cell.json``) under ``out``.

    Raises:
        InputError: ``out`` is no folder, or holds no cell.
    """
    out = Path(out)
    if not out.is_dir():
        raise InputError(out, "folder not found", "pass the --out folder of `eslam sweep`")
    finished, unfinished = [], []
    for status_file in sorted(out.glob(f"*/*/seed*/{CELL_FILE}")):
        folder = status_file.parent
        name = folder.relative_to(out).as_posix()
        try:
            status = json.loads(status_file.read_text(encoding="utf-8"))
            metrics = (
                json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
                if status.get("status") == "done"
                else None
            )
        except (OSError, ValueError, AttributeError) as error:
            unfinished.append(f"{name}: unreadable ({error.__class__.__name__})")
            continue
        if metrics is None:
            error = f" ({status['error']})" if status.get("error") else ""
            unfinished.append(f"{name}: {status.get('status')}{error}")
            continue
        finished.append(
            CellResult(
                status["dataset"],
                status["variant"],
                int(status["seed"]),
                metrics,
                status.get("paper_scene"),
                status.get("paper_experiment"),
            )
        )
    if not finished and not unfinished:
        raise InputError(
            out, "holds no sweep cells (<dataset>/<variant>/seed<k>/cell.json)", "run eslam sweep"
        )
    return SweepCells(tuple(finished), tuple(unfinished))


def mean_std(values: Sequence[float]) -> tuple[float, float | None]:
    """Mean and sample standard deviation sqrt(sum (x - mean)^2 / (n - 1)); None for n = 1."""
    n = len(values)
    mean = math.fsum(values) / n
    if n < 2:
        return mean, None
    return mean, math.sqrt(math.fsum((x - mean) ** 2 for x in values) / (n - 1))


def aggregate(cells: Sequence[CellResult], order: dict | None = None) -> list[dict]:
    """One row per dataset, variant and metric present (ROW_KEYS), ordered by ``order``
    (sweep.json's datasets and variants, first) then by name; metrics in TABLE_METRICS order."""
    groups: dict[tuple[str, str], list[CellResult]] = {}
    for cell in cells:
        groups.setdefault((cell.dataset, cell.variant), []).append(cell)
    rows = []
    for dataset, variant in sorted(groups, key=lambda key: _rank(key, order or {})):
        group = groups[(dataset, variant)]
        scene, experiment = group[0].paper_scene, group[0].paper_experiment
        for metric, _ in TABLE_METRICS:
            values = [float(c.metrics[metric]) for c in group if _number(c.metrics.get(metric))]
            if not values:
                continue
            mean, std = mean_std(values)
            paper = None
            if scene is not None and experiment is not None:
                paper = paper_value(scene, experiment, metric)
            rows.append(
                {
                    "dataset": dataset,
                    "variant": variant,
                    "metric": metric,
                    "mean": mean,
                    "std": std,
                    "n": len(values),
                    "paper": None if paper is None else paper.value,
                    "paper_std": None if paper is None else paper.std,
                    "paper_source": None if paper is None else paper.source,
                }
            )
    return rows


def _number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _rank(key: tuple[str, str], order: dict) -> tuple:
    datasets, variants = order.get("datasets", []), order.get("variants", [])
    dataset, variant = key
    return (
        datasets.index(dataset) if dataset in datasets else len(datasets),
        dataset,
        variants.index(variant) if variant in variants else len(variants),
        variant,
    )


def write_table(out: str | Path, plots: bool = True) -> TableResult:
    """Aggregate the finished cells under ``out`` into table.md/.csv/.json and plots.

    Raises:
        InputError: no cell under ``out``.
        ESLAMError: ``plots`` without matplotlib (the message names the extra).
    """
    out = Path(out)
    cells = collect_cells(out)
    order = {}
    if (out / SWEEP_FILE).is_file():
        order = json.loads((out / SWEEP_FILE).read_text(encoding="utf-8"))
    rows = aggregate(cells.finished, order)
    files = [out / "table.md", out / "table.csv", out / "table.json"]
    if plots:
        figures = _plots(rows, out / "plots")
    write_text(files[0], markdown_table(rows, cells.unfinished, out))
    write_text(files[1], csv_table(rows))
    write_text(files[2], json_text(rows) + "\n")
    if plots:
        files += figures
    return TableResult(tuple(rows), tuple(files), cells.unfinished)


def _plots(rows: Sequence[dict], folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for metric, title in TABLE_METRICS:
        chosen = [row for row in rows if row["metric"] == metric]
        if chosen:
            path = folder / f"{metric}.png"
            plot_metric_bars(chosen, title, path)
            paths.append(path)
    return paths


def _shown(mean: float | None, std: float | None) -> str:
    if mean is None:
        return ""
    return f"{mean:.2f}" if std is None else f"{mean:.2f} ± {std:.2f}"


def markdown_table(rows: Sequence[dict], unfinished: Sequence[str], out: Path) -> str:
    """table.md: per dataset, one line per variant, a column per metric: ours
    (mean ± std over n seeds) and, where matched, the paper's with its source."""
    titles = dict(TABLE_METRICS)
    lines = [
        f"# Sweep {out}",
        "",
        "Mean ± sample std over seeds (n seeds per cell); (paper VALUE [k]) is the "
        "published number of the same experiment, from source k below.",
    ]
    datasets = list(dict.fromkeys(row["dataset"] for row in rows))
    sources: dict[str, int] = {}
    for dataset in datasets:
        chosen = [row for row in rows if row["dataset"] == dataset]
        metrics = [m for m, _ in TABLE_METRICS if any(row["metric"] == m for row in chosen)]
        lines += ["", f"## {dataset}", ""]
        lines.append("| variant | n | " + " | ".join(titles[m] for m in metrics) + " |")
        lines.append("|---|---|" + "---|" * len(metrics))
        for variant in dict.fromkeys(row["variant"] for row in chosen):
            by_metric = {row["metric"]: row for row in chosen if row["variant"] == variant}
            n = max(row["n"] for row in by_metric.values())
            cells = []
            for metric in metrics:
                row = by_metric.get(metric)
                text = "" if row is None else _shown(row["mean"], row["std"])
                if row is not None and row["paper"] is not None:
                    note = sources.setdefault(row["paper_source"], len(sources) + 1)
                    text += f" (paper {_shown(row['paper'], row['paper_std'])} [{note}])"
                cells.append(text)
            lines.append(f"| {variant} | {n} | " + " | ".join(cells) + " |")
    if sources:
        lines += ["", "Paper sources (ESLAM supplementary):", ""]
        lines += [f"({number}) {source}" for source, number in sources.items()]
    if unfinished:
        lines += ["", f"Cells left out ({len(unfinished)}, not finished):", ""]
        lines += [f"- {name}" for name in unfinished]
    return "\n".join(lines) + "\n"


def csv_table(rows: Sequence[dict]) -> str:
    """table.csv: ROW_KEYS columns, one line per row (empty = none)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=ROW_KEYS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({key: "" if row[key] is None else row[key] for key in ROW_KEYS})
    return buffer.getvalue()
