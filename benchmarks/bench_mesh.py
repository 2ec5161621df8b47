"""Seconds to extract a mesh from a learned field at 1 cm and 2 cm, and to cull a mesh.

Extraction: a short synthetic run on the demo scene (``eslam demo``'s sequence: the
procedural room, 160x120, CPU preset; the first ``--frames`` frames, stopped there as
an interruption would, so observed space is what those keyframes saw) or an existing
run folder (``--run-dir``), then :func:`eslam.mesh.extract.extract_mesh` over the
keyframes' observed space at each resolution (``time.perf_counter``, one timed call
each after nothing is cached; vertex colours included).

Culling: :func:`eslam.mesh.cull.visible_vertices` with the "eslam" protocol on
``--cull-vertices`` random points against ``--cull-frames`` frames whose cameras see
none of them, the worst case (every vertex is tested in every frame).

The markdown table is printed and, unless ``--no-append``, appended to
docs/benchmarks.md with the date, the machine and the command line.

Usage:
    python benchmarks/bench_mesh.py [--device cpu|cuda] [--frames N] [--run-dir PATH]
        [--threads N] [--no-append] [--docs PATH] [--note TEXT]
"""

from __future__ import annotations

import argparse
import datetime
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from _machine import (
    DEFAULT_DOCS,
    add_device_argument,
    check_device,
    command_line,
    load_average,
    machine_lines,
    publish,
)

from eslam.config import load_config
from eslam.mesh.cull import CullCameras, CullOptions, visible_vertices
from eslam.mesh.extract import extract_mesh
from eslam.slam.session import run_slam
from eslam.slam.state import SLAMState, load_state
from eslam.synthetic import read_synthetic_bound, write_synthetic_sequence
from eslam.types import Intrinsics
from eslam.workflows.demo import DEMO_CONFIG, DEMO_SCENE

RESOLUTIONS = (0.01, 0.02)
"""Grid steps timed, metres: the release meshes Replica/TUM at 1 cm, ScanNet at 2 cm."""

CULL_CAMERA = Intrinsics(width=1200, height=680, fx=600.0, fy=600.0, cx=599.5, cy=339.5)
"""Replica's camera, for the culling timing."""


def make_run(root: Path, frames: int, device: str) -> Path:
    """The demo scene, run for its first ``frames`` frames; returns the run folder."""
    data = root / "data"
    write_synthetic_sequence(data, DEMO_SCENE, overwrite=True)
    overrides = [
        f"data.path={data}",
        f"scene.bound={read_synthetic_bound(data)}",
        f"device={device}",
        "output.progress=false",
    ]
    run_slam(load_config(DEMO_CONFIG, overrides), root / "run", stop_after=frames)
    return root / "run"


def load_run(run_dir: Path, device: str) -> SLAMState:
    config = load_config(run_dir / "config.yaml")
    return load_state(run_dir / "map.pt", config, torch.device(device))


def time_extraction(state: SLAMState, resolution: float, device: torch.device) -> dict:
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    start = time.perf_counter()
    mesh = extract_mesh(state.field, resolution, state.observed_views())
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return {"seconds": time.perf_counter() - start, "vertices": len(mesh.vertices)}


def time_culling(vertices: int, frames: int, device: str) -> float:
    """Seconds for the 'eslam' protocol, worst case: no frame sees any vertex."""
    rng = np.random.default_rng(0)
    points = rng.uniform(-1.0, 1.0, size=(vertices, 3)) + np.array([0.0, 0.0, -5.0])
    poses = np.repeat(np.eye(4)[None], frames, axis=0)  # looking along +z, points behind
    depth = np.full((CULL_CAMERA.height, CULL_CAMERA.width), 3.0, dtype=np.float32)
    cameras = CullCameras(poses, CULL_CAMERA, (depth for _ in range(frames)))
    start = time.perf_counter()
    visible_vertices(points, cameras, "eslam", CullOptions(device=device))
    return time.perf_counter() - start


def report(rows: dict, cull_s: float, args: argparse.Namespace, facts: dict) -> str:
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    device = torch.device(args.device)
    per_frame = cull_s / args.cull_frames / (args.cull_vertices / 1e6) * 1e3
    lines = [
        f"## bench_mesh, {now}, {device.type}",
        "",
        *machine_lines(device, facts["load"]),
        f"- command: `{facts['command']}`",
        f"- workload: {facts['workload']}; field bound {facts['bound']} m, "
        f"{facts['keyframes']} keyframes of observed space",
    ]
    if args.note:
        lines.append(f"- note: {args.note}")
    lines += [
        "",
        "| step | seconds | size |",
        "|---|---:|---:|",
        *(
            f"| extract_mesh at {r * 100:g} cm | {row['seconds']:.2f} "
            f"| {row['vertices']:,} vertices |"
            for r, row in rows.items()
        ),
        f"| cull ('eslam'), {args.cull_vertices:,} vertices x {args.cull_frames} frames "
        f"(1200x680, none visible) | {cull_s:.2f} | {per_frame:.1f} ms per frame per M vertices |",
    ]
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description="seconds to mesh a learned field and to cull")
    add_device_argument(parser)
    parser.add_argument("--frames", type=int, default=20, help="frames of the demo run")
    parser.add_argument("--run-dir", type=Path, help="time this run folder instead")
    parser.add_argument("--cull-vertices", type=int, default=1_000_000)
    parser.add_argument("--cull-frames", type=int, default=20)
    parser.add_argument("--threads", type=int, default=0, help="0 = torch's default")
    parser.add_argument("--no-append", action="store_true", help="print only")
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--note", default="", help="a remark printed with the machine")
    args = parser.parse_args(argv)
    check_device(parser, args)
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    command = command_line("benchmarks/bench_mesh.py", argv)
    load_start = load_average()
    with tempfile.TemporaryDirectory() as scratch:
        if args.run_dir is None:
            run_dir = make_run(Path(scratch), args.frames, args.device)
            workload = f"demo scene (160x120), first {args.frames} frames, CPU preset"
        else:
            run_dir, workload = args.run_dir, f"run folder {args.run_dir}"
        if args.threads > 0:  # the run set its configured threads
            torch.set_num_threads(args.threads)
        state = load_run(run_dir, args.device)
        device = torch.device(args.device)
        rows = {r: time_extraction(state, r, device) for r in RESOLUTIONS}
    cull_s = time_culling(args.cull_vertices, args.cull_frames, args.device)
    facts = {
        "command": command,
        "workload": workload,
        "bound": [[round(v, 3) for v in row] for row in state.field.bound.cpu().tolist()],
        "keyframes": len(state.keyframes),
        "load": (load_start, load_average()),
    }
    section = report(rows, cull_s, args, facts)
    publish(section, args.docs, args.no_append)


if __name__ == "__main__":
    main()
