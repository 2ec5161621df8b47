"""The run loop: track every frame, map every k-th, write the run folder (design.md).

Single process, sequential, seeded. The loop alone orchestrates; tracking, mapping,
keyframes, rendering and losses are called from here and know nothing of each other.
A checkpoint (map.pt) is written every ``output.checkpoint_every`` frames and at the
end; ``resume=True`` continues from it and ends with the same outputs (and, on CPU,
the same trajectory) as an uninterrupted run.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from eslam.config import ESLAMConfig, save_config
from eslam.data import RGBDSequence, open_sequence
from eslam.errors import ConfigError
from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.geometry.pose import extrapolate_constant_velocity
from eslam.io.run_dir import RunDirectory, write_json
from eslam.io.trajectory import write_tum_trajectory
from eslam.render.rays import camera_directions
from eslam.slam.mapping import MappingSettings, map_window
from eslam.slam.progress import RunProgress, peak_memory_mb
from eslam.slam.state import SLAMState, initial_state, load_state, save_state
from eslam.slam.tracking import TrackingSettings, track_frame
from eslam.slam.views import View, make_view

log = logging.getLogger("eslam")


@dataclass(frozen=True)
class RunResult:
    """What a finished run produced.

    Attributes:
        run_dir: the run folder.
        poses: (N, 4, 4) estimated camera-to-world poses.
        metrics: the contents of metrics.json.
    """

    run_dir: Path
    poses: np.ndarray
    metrics: dict


def _device(name: str) -> torch.device:
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError(f"device '{name}' asked for, but torch sees no CUDA device (use cpu)")
    return device


def _frame_view(frame, directions: torch.Tensor, device: torch.device, border: int) -> View:
    rgb = torch.from_numpy(frame.rgb).to(device).float() / 255.0
    depth = torch.from_numpy(frame.depth).to(device)
    return make_view(rgb, depth, directions, border)


def _is_mapped(index: int, frames: int, every: int) -> bool:
    return index % every == 0 or index == frames - 1


def run_slam(
    config: ESLAMConfig,
    run_dir: str | Path,
    resume: bool = False,
    stop_after: int | None = None,
) -> RunResult:
    """Run ESLAM on ``config.data`` and write the run folder ``run_dir``.

    Args:
        config: the fully resolved configuration (saved as config.yaml).
        run_dir: output folder (created); see :class:`~eslam.io.run_dir.RunDirectory`.
        resume: continue from ``run_dir/map.pt`` instead of starting afresh.
        stop_after: stop (checkpointed) after this many frames in total, as an
            interruption would; used by tests of ``resume``.
    """
    if config.data.path is None:
        raise ConfigError("data.path is not set (pass --data PATH or set data.path in the config)")
    if config.threads > 0:
        torch.set_num_threads(config.threads)
    device = _device(config.device)
    sequence = open_sequence(config.data.format, config.data.path)
    run = RunDirectory(Path(run_dir))
    run.root.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(run.log, mode="a", encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    try:
        if resume:
            state = load_state(run.map, config, device)
            log.info("resuming %s at frame %d", config.data.path, state.next_frame)
        else:
            save_config(config, run.config)
            state = initial_state(config, sequence, device)
            log.info("run on %s: %d frames, device %s", config.data.path, len(sequence), device)
        _process(config, sequence, state, run, device, stop_after)
        result = _finish(config, sequence, state, run, device)
        log.info("metrics %s", result.metrics)
        return result
    finally:
        log.removeHandler(handler)
        handler.close()


def _process(
    config: ESLAMConfig,
    sequence: RGBDSequence,
    state: SLAMState,
    run: RunDirectory,
    device: torch.device,
    stop_after: int | None,
) -> None:
    frames = len(sequence)
    end = frames if stop_after is None else min(frames, stop_after)
    directions = camera_directions(sequence.intrinsics, device)
    tracking = TrackingSettings(config.tracking, config.render, config.loss)
    mapping = MappingSettings(config.mapping, config.render, config.loss)
    gt = sequence.gt_poses()
    progress = RunProgress(frames, state.next_frame, config.output.progress, gt)
    for index in range(state.next_frame, end):
        frame = sequence[index]
        start = time.perf_counter()
        if index == 0:
            pose = torch.eye(4) if gt is None else torch.from_numpy(gt[0]).float()
            pose = pose.to(device)
        else:
            view = _frame_view(frame, directions, device, config.tracking.border)
            previous = state.poses[index - 1]
            initial = previous
            if config.tracking.constant_velocity and index >= 2:
                initial = extrapolate_constant_velocity(state.poses[index - 2], previous)
            if len(view.candidates) == 0:
                log.warning("frame %d has no valid depth: pose predicted, not tracked", index)
                pose = initial
            else:
                pose = track_frame(state.field, view, initial, tracking, state.generator).pose
        state.poses[index] = pose
        tracked = time.perf_counter()
        if _is_mapped(index, frames, config.mapping.every):
            _map(config, state, frame, index, directions, mapping, device)
        mapped = time.perf_counter()
        state.tracking_time.append(tracked - start)
        state.mapping_time.append(mapped - tracked)
        state.next_frame = index + 1
        progress.update(index, state.poses[: index + 1])
        if state.next_frame % config.output.checkpoint_every == 0 or state.next_frame == end:
            save_state(run.map, state)
            log.info("checkpoint after frame %d", index)
    progress.close()


def _map(
    config: ESLAMConfig,
    state: SLAMState,
    frame,
    index: int,
    directions: torch.Tensor,
    settings: MappingSettings,
    device: torch.device,
) -> None:
    store = state.keyframes
    current = store.add(frame, state.poses[index])
    window = state.window.select(store, current, state.generator)
    views = [
        make_view(store.rgb(k, device), store.depth(k, device), directions, border=0)
        for k in window
    ]
    oldest = min(window, key=lambda k: store.frame_indices[k])
    optimise = [config.mapping.optimise_poses and k != oldest for k in window]
    first = len(store) == 1
    result = map_window(
        state.field,
        views,
        torch.stack([store.poses[k] for k in window]).to(device),
        optimise,
        settings,
        iterations=config.mapping.first_iterations if first else config.mapping.iterations,
        lr_factor=config.mapping.first_lr_factor if first else 1.0,
        generator=state.generator,
    )
    log.info("mapped frame %d: window %s, loss %.5f", index, list(window), result.loss)
    for k, pose, moved in zip(window, result.poses, optimise, strict=True):
        if moved:
            store.set_pose(k, pose)
            state.poses[store.frame_indices[k]] = pose


def _finish(
    config: ESLAMConfig,
    sequence: RGBDSequence,
    state: SLAMState,
    run: RunDirectory,
    device: torch.device,
) -> RunResult:
    done = state.next_frame
    poses = state.poses[:done].detach().cpu().double().numpy()
    timestamps = np.array([float(i) for i in range(done)])
    write_tum_trajectory(run.trajectory, timestamps, poses)
    gt = sequence.gt_poses()
    metrics: dict = {
        "frames": done,
        "device": str(device),
        "fpt_s": float(np.sum(state.tracking_time) + np.sum(state.mapping_time)) / max(done, 1),
        "peak_memory_mb": peak_memory_mb(device),
    }
    if gt is not None:
        write_tum_trajectory(run.trajectory_gt, timestamps, gt[:done])
        if done >= 3:
            metrics.update(absolute_trajectory_error(poses, gt[:done]).as_cm())
    write_json(
        run.timings,
        {"tracking_s": list(state.tracking_time), "mapping_s": list(state.mapping_time)},
    )
    if config.output.mesh and done == len(sequence):
        from eslam.data.mesh_io import write_mesh_ply
        from eslam.mesh.extract import extract_mesh

        mesh = extract_mesh(state.field, config.output.mesh_resolution, state.observed_views())
        write_mesh_ply(run.mesh, mesh)
    write_json(run.metrics, metrics)
    return RunResult(run_dir=run.root, poses=poses, metrics=metrics)
