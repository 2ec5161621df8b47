"""Bar plots of a sweep's table (``eslam table``): one PNG per metric.

matplotlib (the ``[viz]`` extra) is imported when a plot is drawn, with the Agg
backend (:func:`eslam.viz.plots._pyplot`'s guard). Images are written atomically.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from eslam.atomic import write_with
from eslam.viz.plots import _pyplot


def plot_metric_bars(rows: Sequence[dict], title: str, path: str | Path) -> None:
    """Bars of one metric: a group per dataset, a bar per variant (mean, std as error
    bar), the paper's value as a black mark where the row has one.

    Args:
        rows: table rows of one metric (keys dataset, variant, mean, std, paper).
        title: the metric's name with its unit (the y axis).
        path: PNG file to write.
    """
    plt = _pyplot()
    datasets = list(dict.fromkeys(row["dataset"] for row in rows))
    variants = list(dict.fromkeys(row["variant"] for row in rows))
    width = 0.8 / max(len(variants), 1)
    figure, axes = plt.subplots(figsize=(max(5.0, 1.2 * len(datasets) * len(variants)), 4))
    colours = plt.get_cmap("tab10")
    for v, variant in enumerate(variants):
        chosen = [row for row in rows if row["variant"] == variant]
        xs = [
            datasets.index(row["dataset"]) + (v - (len(variants) - 1) / 2) * width for row in chosen
        ]
        errors = [row["std"] or 0.0 for row in chosen]
        means = [row["mean"] for row in chosen]
        axes.bar(xs, means, width, yerr=errors, capsize=3, label=variant, color=colours(v % 10))
        papers = [
            (x, row["paper"]) for x, row in zip(xs, chosen, strict=True) if row["paper"] is not None
        ]
        if papers:
            axes.plot(*zip(*papers, strict=True), "k_", ms=14, mew=2)
    if any(row["paper"] is not None for row in rows):
        axes.plot([], [], "k_", ms=14, mew=2, label="paper")
    axes.set_xticks(range(len(datasets)), datasets)
    axes.set_ylabel(title)
    axes.legend(fontsize="small", ncols=min(len(variants) + 1, 5))
    figure.tight_layout()
    write_with(path, lambda temporary: figure.savefig(temporary, format="png", dpi=100))
    plt.close(figure)
