"""Named stages of an optimisation iteration, for profiling (benchmarks/bench_core.py).

Each stage is a ``torch.profiler.record_function`` region: free of host syncs, and
about a microsecond when no profiler runs. The regions never nest, so a profiler's
per-region totals add up to the time of the stages; what lies outside every region is
Python glue and small tensor ops.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch

STAGES = (
    "ray sampling",
    "plane sampling",
    "decoders",
    "rendering",
    "loss",
    "backward",
    "optimiser step",
)
"""Stages of a tracking or mapping iteration, in the order they run."""

PREFIX = "eslam:"
"""Region names are ``PREFIX + stage``."""


def stage(name: str) -> torch.profiler.record_function:
    """The profiler region of stage ``name`` (one of :data:`STAGES`), a context manager."""
    if name not in STAGES:
        raise ValueError(f"unknown stage {name!r}; stages are {', '.join(STAGES)}")
    return torch.profiler.record_function(PREFIX + name)


def stage_totals(events: Iterable[object]) -> dict[str, float]:
    """Microseconds of host time per stage, summed over profiler events.

    Args:
        events: ``torch.profiler.profile(...).events()`` (or ``key_averages()``): any
            objects with ``name`` and ``cpu_time_total`` (microseconds).

    Returns:
        Every stage of :data:`STAGES`, 0 for one that never ran.
    """
    totals = dict.fromkeys(STAGES, 0.0)
    for event in events:
        name = getattr(event, "name", "")
        if name.startswith(PREFIX) and name[len(PREFIX) :] in totals:
            totals[name[len(PREFIX) :]] += float(getattr(event, "cpu_time_total", 0.0))
    return totals
