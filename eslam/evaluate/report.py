"""Plain-text tables of metrics for the terminal."""

from __future__ import annotations

from collections.abc import Mapping


def _shown(value: object) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4f}"
    return str(value)


def metrics_table(title: str, metrics: Mapping[str, object]) -> str:
    """A title line and one aligned ``name  value`` line per metric.

    Example::

        ATE (se3 alignment)
          ate_rmse_cm     1.3470
          pairs           785
    """
    width = max((len(name) for name in metrics), default=0)
    lines = [title] + [f"  {name:<{width}}  {_shown(value)}" for name, value in metrics.items()]
    return "\n".join(lines)
