"""Loop closure on the synthetic loop: ATE, loops and mesh with it off and on (docs/loops.md).

The room's loop trajectory (``eslam synth --trajectory loop``: laps around the room
looking outwards, about 250 frames a lap at 1 cm a frame) is rendered with exact ground
truth, ``--frames`` frames at ``--size``, with ``--focal-error`` (the frames report a
focal length that much off: odometry drifts) and the sensor flaws ``--depth-noise`` and
``--missing-depth``. Each ``--settings`` entry is one run and one markdown row: ``off``
(the config as it is), ``on`` (``mapping.loops.enabled=true``) or ``key=value`` entries,
comma-separated, after either or alone (``on,seed=1``). A row: ATE, and without
alignment (frame 0 starts at its ground truth, and the mesh is scored where the run put
it) the position error's RMSE, where the camera is back at its start and the largest,
loops accepted / refused / closed, wall time; with ``--profile N`` a line of each run's
position error every N frames; with ``--mesh`` the mesh's accuracy and completion
against the scene's mesh (``eslam eval``'s, the ``eval`` extra; ``eslam eval RUN
--gt-mesh DATA/mesh.ply --views V --max-unobserved F`` adds the depth L1).

    python benchmarks/loop_closure.py --out /tmp/loops --focal-error 0.02

Prints the table only (docs/results.md takes its rows by hand).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from eslam.cli.args import image_size
from eslam.errors import ESLAMError
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig, write_synthetic_sequence
from eslam.synthetic.runs import synthetic_run_config
from eslam.synthetic.scenes import build_scene
from eslam.synthetic.trajectory import loop_lap_frames
from eslam.workflows.demo import DEMO_CONFIG

PRESETS = {"off": (), "on": ("mapping.loops.enabled=true",)}


def expand(name: str) -> tuple[str, ...]:
    """A ``--settings`` entry as overrides: ``off`` and ``on`` (PRESETS) may start a
    comma list of ``key=value`` entries (``on,seed=1``)."""
    return tuple(o for item in name.split(",") for o in PRESETS.get(item, (item,)))


def mesh_cells(run_dir: Path, data: Path) -> str:
    """Accuracy and completion (cm) of the run's mesh against the scene's."""
    from eslam.workflows.evaluate_run import EvaluationOptions, evaluate_run

    options = EvaluationOptions(gt_mesh=data / "mesh.ply", depth_l1_views=0)
    metrics = evaluate_run(run_dir, options)
    return f" | {metrics['accuracy_cm']:.2f} | {metrics['completion_cm']:.2f}"


def position_errors(run_dir: Path) -> np.ndarray:
    """Each frame's position error (cm), frame 0 at its ground truth (no alignment)."""
    estimate = np.loadtxt(run_dir / "trajectory.txt")
    truth = np.loadtxt(run_dir / "trajectory_gt.txt")
    return 100.0 * np.linalg.norm(estimate[:, 1:4] - truth[:, 1:4], axis=1)


def row(name: str, run_dir: Path, lap: int, metrics: dict, wall: float) -> str:
    """One markdown row for the run in ``run_dir`` (module doc), without the mesh."""
    errors = position_errors(run_dir)
    back = f"{errors[lap]:.2f}" if lap < len(errors) else "-"
    loops = "-"
    if "loops_accepted" in metrics:
        loops = (
            f"{metrics['loops_accepted']} / {metrics['loops_rejected']} / {metrics['loops_closed']}"
        )
    return (
        f"| {name} | {metrics['ate_rmse_cm']:.2f} | {np.sqrt(np.mean(errors**2)):.2f} | {back} "
        f"| {errors.max():.2f} | {loops} "
        f"| {wall / 60:.1f}"
    )


def profile(name: str, run_dir: Path, every: int) -> str:
    """One line: the run's position error (cm) at frames 0, every, 2 every, ..."""
    errors = position_errors(run_dir)
    cells = " ".join(f"{k}:{errors[k]:.2f}" for k in range(0, len(errors), every))
    return f"{name}: position error (cm) by frame {cells}"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for data and runs")
    parser.add_argument("--config", type=Path, default=DEMO_CONFIG, help="(configs/demo.yaml)")
    parser.add_argument("--size", type=image_size, default=(160, 120), help="WxH (160x120)")
    parser.add_argument("--frames", type=int, default=300, help="frames (300: a lap and more)")
    parser.add_argument("--focal-error", type=float, default=0.0)
    parser.add_argument("--depth-noise", action="store_true")
    parser.add_argument("--missing-depth", action="store_true")
    parser.add_argument("--settings", nargs="+", default=["off", "on"])
    parser.add_argument("--mesh", action="store_true", help="score the meshes (eval extra)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--profile", type=int, metavar="N", help="also print each run's error every N frames"
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    loop = SynthConfig(
        frames=args.frames,
        width=args.size[0],
        height=args.size[1],
        trajectory="loop",
        focal_error=args.focal_error,
        depth_noise=args.depth_noise,
        missing_depth=args.missing_depth,
    )
    lap = loop_lap_frames(build_scene(loop.scene, loop.seed), replace(loop, frames=1))
    data = args.out / "data"
    if not (data / "synth.json").is_file():
        write_synthetic_sequence(data, loop, overwrite=True)
    head = "| loop closure | ATE RMSE (cm) | RMSE without alignment (cm) "
    head += "| error back at the start (cm) | largest error (cm) "
    head += "| loops accepted / refused / closed | wall (min)"
    rule = "|---|---:|---:|---:|---:|---:|---:"
    if args.mesh:
        head, rule = head + " | mesh accuracy (cm) | completion (cm)", rule + "|---:|---:"
    lines = [head + " |", rule + "|"]
    try:  # every setting is checked before the first run starts
        configs = [
            synthetic_run_config(args.config, data, *expand(name), mesh=args.mesh)
            for name in args.settings
        ]
    except ESLAMError as error:
        parser.exit(2, f"loop_closure.py: {error}\n")
    for index, (name, config) in enumerate(zip(args.settings, configs, strict=True)):
        run_dir = args.out / f"run-{index}"
        start = time.perf_counter()
        metrics = run_slam(config, run_dir, overwrite=True).metrics
        line = row(name, run_dir, lap, metrics, time.perf_counter() - start)
        if args.mesh:
            line += mesh_cells(run_dir, data)
        lines.append(line + " |")
        print(lines[-1], flush=True)
        if args.profile:
            print(profile(name, run_dir, args.profile), flush=True)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
