"""A run's config on a synthetic sequence: the sequence's known bound, no mesh, no
progress bar (what tests and the synthetic benchmarks run with)."""

from __future__ import annotations

from pathlib import Path

from eslam.config import ESLAMConfig, load_config
from eslam.synthetic.files import read_synthetic_bound


def synthetic_run_config(
    config: str | Path, sequence: Path, *extra: str, mesh: bool = False
) -> ESLAMConfig:
    """``config`` on the synthetic ``sequence`` (``eslam synth``'s layout) with its
    bound from synth.json, ``output.mesh`` = ``mesh``, no progress bar, then ``extra``."""
    return load_config(
        config,
        [
            f"data.path={sequence}",
            f"scene.bound={read_synthetic_bound(sequence)}",
            f"output.mesh={str(mesh).lower()}",
            "output.progress=false",
            *extra,
        ],
    )
