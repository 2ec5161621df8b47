"""Does a change keep the trajectories? One config run by two commits of this repo.

The working tree's code and the code of ``--base`` (any git revision; checked out with
``git worktree`` into a temporary folder, removed afterwards) each run ``--config``
on ``--data`` in a fresh process (seeded, CPU, 1 thread, no mesh), each with its own
copy of the packaged configs; the poses are compared frame by frame. Prints the ATE of
each and the largest difference of any pose element and of any position (metres).

    python benchmarks/same_trajectory.py --base 07f55ab --config sevenscenes/redkitchen_cpu.yaml \\
        --data ../shared/data/7scenes-redkitchen data.max_frames=100 tracking.method=render

``--config`` is a packaged config's path under configs/ (read from each tree's own
configs/); exit status 1 when the positions differ by more than ``--tolerance``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

RUN = """
import sys, json, numpy as np, torch
torch.set_num_threads(1)
from eslam.config import load_config
from eslam.slam.{module} import run_slam
config, out, *overrides = sys.argv[1:]
result = run_slam(load_config(config, overrides), out)
np.save(out + ".npy", result.poses)
print(json.dumps(result.metrics.get("ate_rmse_cm")))
"""


def run_tree(tree: Path, config: str, data: Path, out: Path, overrides: list[str]) -> float:
    """Run ``config`` (a path under the tree's configs/) with the code of ``tree``; the
    poses are saved to ``out``.npy; returns the ATE RMSE (cm)."""
    module = "session" if (tree / "eslam" / "slam" / "session.py").is_file() else "loop"
    settings = [f"data.path={data}", "device=cpu", "output.mesh=false", "output.progress=false"]
    command = [
        sys.executable,
        "-c",
        RUN.format(module=module),
        str(tree / "configs" / config),
        str(out),
        *settings,
        *overrides,
    ]
    environment = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        command, cwd=out.parent, env=environment, capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise SystemExit(f"{tree}: the run failed:\n{done.stderr[-2000:]}")
    return float(json.loads(done.stdout.strip().splitlines()[-1]))


def compare(base: str, config: str, data: Path, overrides: list[str]) -> dict:
    """Run both trees (module doc); the ATEs and the largest differences."""
    with tempfile.TemporaryDirectory(prefix="same-trajectory-") as scratch:
        folder = Path(scratch)
        worktree = folder / "base"
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(worktree), base],
            cwd=ROOT,
            check=True,
            capture_output=True,
        )
        try:
            base_ate = run_tree(worktree, config, data, folder / "base-run", overrides)
            new_ate = run_tree(ROOT, config, data, folder / "new-run", overrides)
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(worktree)], cwd=ROOT, check=False
            )
        before = np.load(folder / "base-run.npy")
        after = np.load(folder / "new-run.npy")
    if before.shape != after.shape:
        raise SystemExit(f"the runs have {len(before)} and {len(after)} poses")
    return {
        "frames": len(after),
        "ate_base_cm": base_ate,
        "ate_cm": new_ate,
        "max_pose_element_diff": float(np.abs(before - after).max()),
        "max_position_diff_m": float(np.abs(before[:, :3, 3] - after[:, :3, 3]).max()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--base", required=True, help="git revision to compare with")
    parser.add_argument("--config", required=True, help="path under configs/, e.g. demo.yaml")
    parser.add_argument("--data", type=Path, required=True, help="the sequence folder")
    parser.add_argument("--tolerance", type=float, default=1e-6, help="metres (1e-6)")
    parser.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    args = parser.parse_intermixed_args(argv)
    if not (ROOT / "configs" / args.config).is_file():
        parser.error(f"configs/{args.config} does not exist")
    if not args.data.is_dir():
        parser.error(f"--data {args.data} is not a folder")
    result = compare(args.base, args.config, args.data.resolve(), list(args.overrides))
    print(json.dumps(result, indent=2))
    return 0 if result["max_position_diff_m"] <= args.tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
