"""A peer on the same frames: Open3D's dense RGB-D SLAM (frame-to-model ICP on a TSDF
voxel-block grid, ``open3d.t.pipelines.slam``, the settings of Open3D's own
``dense_slam.py`` example) on the frames eslam reads with ``--config``, with its ATE
and RPE computed as eslam's runs compute theirs.

The frames come through eslam's reader (the same association, undistortion and size
as an eslam run of that config), so the two trajectories compare frame for frame.
Writes ``trajectory.txt`` (TUM format) and ``metrics.json`` (frames, ATE, RPE, frames
per second, machine) into ``--out`` and prints one markdown row.

    pip install "eslam[bench]"   # Open3D
    python benchmarks/open3d_slam.py --config tum/tum_cpu \\
        --data .../rgbd_dataset_freiburg1_xyz --out /tmp/open3d_fr1_xyz [--frames 200] \\
        [data.pairing=release]

Trailing KEY=VALUE arguments override ``--config`` (how its frames are read).

Open3D's defaults (its example): voxel 3/512 m, 16^3 voxels a block, 40000 blocks,
depth 0.1-3 m, truncation 8 voxels, ICP distance threshold 0.07 m.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import cpu_model

from eslam.atomic import write_text
from eslam.config import load_config
from eslam.data import open_sequence
from eslam.errors import ESLAMError
from eslam.evaluate.trajectory import absolute_trajectory_error, relative_pose_error
from eslam.io.trajectory import write_tum_trajectory
from eslam.types import Frame, Intrinsics

DEPTH_SCALE = 1000.0
"""Depth units per metre of the uint16 images handed to Open3D (millimetres)."""


def open3d() -> Any:
    """The ``open3d`` module, or exit 2 with the line that installs it."""
    try:
        import open3d as o3d
    except ImportError:
        print("benchmarks/open3d_slam.py needs Open3D: pip install 'eslam[bench]'", file=sys.stderr)
        raise SystemExit(2) from None
    return o3d


def intrinsic_matrix(o3d: Any, intrinsics: Intrinsics) -> Any:
    """The 3x3 pinhole K as an Open3D tensor (float64)."""
    k = np.array(
        [
            [intrinsics.fx, 0.0, intrinsics.cx],
            [0.0, intrinsics.fy, intrinsics.cy],
            [0.0, 0.0, 1.0],
        ]
    )
    return o3d.core.Tensor(k, o3d.core.Dtype.Float64)


def images(o3d: Any, frame: Frame) -> tuple[Any, Any]:
    """A frame's depth (uint16 millimetres) and colour as Open3D images."""
    depth = np.rint(np.nan_to_num(frame.depth) * DEPTH_SCALE).clip(0, 65535).astype(np.uint16)
    return (
        o3d.t.geometry.Image(o3d.core.Tensor(depth)),
        o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(frame.rgb))),
    )


def track(o3d: Any, frames: list[Frame], args: argparse.Namespace) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses from Open3D's frame-to-model SLAM, the first the
    first frame's ground truth (identity without one), as eslam's runs start."""
    device = o3d.core.Device("CPU:0")
    first = frames[0].pose_gt if frames[0].pose_gt is not None else np.eye(4)
    pose = o3d.core.Tensor(np.eye(4))
    model = o3d.t.pipelines.slam.Model(
        args.voxel, args.block_resolution, args.block_count, pose, device
    )
    height, width = frames[0].depth.shape
    k = intrinsic_matrix(o3d, frames[0].intrinsics)
    frame_in = o3d.t.pipelines.slam.Frame(height, width, k, device)
    rendered = o3d.t.pipelines.slam.Frame(height, width, k, device)
    poses = []
    for index, frame in enumerate(frames):
        depth, colour = images(o3d, frame)
        frame_in.set_data_from_image("depth", depth)
        frame_in.set_data_from_image("color", colour)
        if index > 0:
            result = model.track_frame_to_model(
                frame_in, rendered, DEPTH_SCALE, args.depth_max, args.icp_distance
            )
            pose = pose @ result.transformation
        poses.append(first @ pose.cpu().numpy())
        model.update_frame_pose(index, pose)
        model.integrate(frame_in, DEPTH_SCALE, args.depth_max, args.trunc_voxels)
        model.synthesize_model_frame(
            rendered, DEPTH_SCALE, args.depth_min, args.depth_max, args.trunc_voxels, False
        )
    return np.stack(poses)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--config", default="tum/tum_cpu", help="eslam config that reads the data")
    parser.add_argument("--data", type=Path, required=True, help="sequence folder")
    parser.add_argument("--out", type=Path, required=True, help="folder for the results")
    parser.add_argument("--frames", type=int, help="the first N frames (default: all)")
    parser.add_argument("--voxel", type=float, default=3.0 / 512)
    parser.add_argument("--block-resolution", type=int, default=16)
    parser.add_argument("--block-count", type=int, default=40000)
    parser.add_argument("--depth-min", type=float, default=0.1)
    parser.add_argument("--depth-max", type=float, default=3.0)
    parser.add_argument("--trunc-voxels", type=float, default=8.0)
    parser.add_argument("--icp-distance", type=float, default=0.07)
    parser.add_argument("--threads", type=int, default=1, help="(Open3D: OMP_NUM_THREADS)")
    parser.add_argument("overrides", nargs="*", help="KEY=VALUE overrides of --config")
    args = parser.parse_args(argv)
    o3d = open3d()
    torch.set_num_threads(args.threads)
    try:
        config = load_config(args.config, [*args.overrides, f"data.path={args.data}"])
        sequence = open_sequence(config.data)
        count = len(sequence) if args.frames is None else min(args.frames, len(sequence))
        frames = [sequence[i] for i in range(count)]
    except ESLAMError as error:
        print(f"open3d_slam.py: {error}", file=sys.stderr)
        raise SystemExit(2) from None
    if count < 3:
        parser.error("needs at least 3 frames")
    began = time.perf_counter()
    poses = track(o3d, frames, args)
    seconds = time.perf_counter() - began
    metrics: dict = {
        "system": f"Open3D {o3d.__version__} dense RGB-D SLAM",
        "frames": count,
        "fps": count / seconds,
        "machine": f"{cpu_model()}, {args.threads} thread(s), Open3D on its CPU device",
    }
    truth = [f.pose_gt for f in frames]
    if all(t is not None and np.isfinite(t).all() for t in truth):
        gt = np.stack(truth)
        metrics.update(absolute_trajectory_error(poses, gt).as_cm())
        metrics.update(relative_pose_error(poses, gt).as_dict())
    args.out.mkdir(parents=True, exist_ok=True)
    write_tum_trajectory(args.out / "trajectory.txt", [f.timestamp for f in frames], poses)
    write_text(args.out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    ate = f"{metrics['ate_rmse_cm']:.2f} cm" if "ate_rmse_cm" in metrics else "-"
    fps = f"{metrics['fps']:.2f}"
    print(f"| {metrics['system']} | {count} | {ate} | {fps} | {metrics['machine']} |")


if __name__ == "__main__":
    main()
