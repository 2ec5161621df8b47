"""ATE RMSE of the tests' tiny synthetic run over several seeds (spread of a version).

Runs whichever eslam is importable (set PYTHONPATH to a checkout to measure another
version) on a 24-frame 80x60 synthetic scene with the tests' tiny settings:

    python benchmarks/seed_spread.py --seeds 0 14
    PYTHONPATH=/path/to/old/checkout python benchmarks/seed_spread.py --old-keys
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
from pathlib import Path

import torch

TINY = [
    "tracking.border=4",
    "mapping.rays=400",
    "mapping.every=3",
    "mapping.window=4",
    "mapping.iterations=6",
    "mapping.first_iterations=60",
    "render.samples_stratified=12",
    "render.samples_surface=6",
    "output.progress=false",
    "output.mesh=false",
    "field.geometry_resolution=[0.24,0.12]",
    "field.appearance_resolution=[0.24,0.12]",
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs=2, default=[0, 14], help="range [a, b)")
    parser.add_argument(
        "--old-keys", action="store_true", help="tracking.rays/iterations (before 2026-12)"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    from eslam.config import load_config
    from eslam.slam.session import run_slam
    from eslam.workflows.demo import DEMO_CONFIG

    try:
        from eslam.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
    except ImportError:  # before eslam.synthetic existed
        from eslam.data.synthetic import (  # type: ignore[no-redef]
            SynthConfig,
            read_synthetic_bound,
            write_synthetic_sequence,
        )

    prefix = "tracking." if args.old_keys else "tracking.render."
    tracking = [f"{prefix}rays=200", f"{prefix}iterations=8"]
    root = Path(tempfile.mkdtemp())
    write_synthetic_sequence(root / "data", SynthConfig(frames=24, width=80, height=60, seed=3))
    bound = read_synthetic_bound(root / "data")
    ate = {}
    for seed in range(*args.seeds):
        config = load_config(
            DEMO_CONFIG,
            [f"data.path={root / 'data'}", f"scene.bound={bound}", f"seed={seed}", *TINY,
             *tracking],
        )  # fmt: skip
        ate[seed] = run_slam(config, root / f"run{seed}").metrics["ate_rmse_cm"]
    values = list(ate.values())
    print(json.dumps(ate))
    print(f"mean {statistics.mean(values):.3f} cm, std {statistics.stdev(values):.3f} cm")


if __name__ == "__main__":
    main()
