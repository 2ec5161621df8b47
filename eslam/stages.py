"""Named stages of an optimisation iteration, for profiling (benchmarks/bench_core.py).

Each stage is a ``torch.profiler.record_function`` region: free of host syncs, and
about a microsecond when no profiler runs. The regions never nest, so a profiler's
per-region totals add up to the time of the stages; what lies outside every region is
Python glue and small tensor ops.
"""

from __future__ import annotations

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
