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
from eslam.config.device import resolve_device
from eslam.data import RGBDSequence, open_sequence, sequence_timestamps
from eslam.errors import ConfigError, InputError
from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.geometry.pose import extrapolate_constant_velocity
from eslam.io.run_dir import RunDirectory, prepare_run_directory, write_json
from eslam.io.trajectory import write_tum_trajectory
from eslam.render.rays import camera_directions
from eslam.slam.bounds_policy import cover_keyframe, first_pose
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


def _frame_view(frame, directions: torch.Tensor, device: torch.device, border: int) -> View:
    rgb = torch.from_numpy(frame.rgb).to(device).float() / 255.0
    depth = torch.from_numpy(frame.depth).to(device)
    return make_view(rgb, depth, directions, border)


def _is_mapped(index: int, frames: int, every: int) -> bool:
    return index % every == 0 or index == frames - 1


def _frame_name(sequence: RGBDSequence, index: int) -> str:
    timestamps = sequence_timestamps(sequence)
    return f"timestamp {timestamps[index]:.6f}"


def finite_ate_pairs(estimated: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(N,) bool: frames whose estimated and ground-truth poses are both finite.

    Frames without usable ground truth (NaN rows, e.g. ScanNet's lost tracking) are kept
    out of the ATE.
    """
    return np.isfinite(estimated).all(axis=(1, 2)) & np.isfinite(gt).all(axis=(1, 2))


def run_slam(
    config: ESLAMConfig,
    run_dir: str | Path,
    resume: bool = False,
    stop_after: int | None = None,
    overwrite: bool = False,
) -> RunResult:
    """Run ESLAM on ``config.data`` and write the run folder ``run_dir``.

    The input is checked before anything is written (the sequence opens, its first
    and last frames read and pass the reader's checks), so bad input leaves an earlier
    run in ``run_dir`` untouched.

    Args:
        config: the fully resolved configuration (saved as config.yaml).
        run_dir: output folder (created); see :class:`~eslam.io.run_dir.RunDirectory`.
        resume: continue from ``run_dir/map.pt`` instead of starting afresh.
        stop_after: stop (checkpointed) after this many frames in total, as an
            interruption would; used by tests of ``resume``.
        overwrite: start a new run in a folder that already holds one (its files are
            replaced one by one as the new run writes them).

    Raises:
        ConfigError, InputError: bad configuration or input, before any file is written.
    """
    if config.data.path is None:
        raise ConfigError("data.path is not set (pass --data PATH or set data.path in the config)")
    if config.threads > 0:
        torch.set_num_threads(config.threads)
    device = resolve_device(config.device)
    sequence = open_sequence(config.data)
    preflight(sequence)
    run = RunDirectory(Path(run_dir)) if resume else prepare_run_directory(run_dir, overwrite)
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


def preflight(sequence: RGBDSequence) -> None:
    """Read the first and last frames of ``sequence``: the reader's checks raise on bad input.

    Opening a sequence already checked its layout, file pairs and poses; reading two
    frames checks the images (readable, sizes, depth units) before a run writes anything.

    Raises:
        InputError: no frames, or a frame fails its reader's checks.
    """
    if len(sequence) == 0:
        raise InputError(sequence.root, "holds no frames", "check the --data path and its layout")
    sequence[0]
    if len(sequence) > 1:
        sequence[len(sequence) - 1]


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
        has_depth = bool(frame.valid_depth.any())
        if not has_depth:
            log.warning(
                "frame %d (%s) has no valid depth: skipped (pose predicted, not tracked or mapped)",
                index,
                _frame_name(sequence, index),
            )
        if index == 0:
            pose = first_pose(sequence).to(device)
        else:
            previous = state.poses[index - 1]
            initial = previous
            if config.tracking.constant_velocity and index >= 2:
                initial = extrapolate_constant_velocity(state.poses[index - 2], previous)
            view = _frame_view(frame, directions, device, config.tracking.border)
            if not has_depth or len(view.candidates) == 0 or len(state.keyframes) == 0:
                pose = initial
            else:
                pose = track_frame(state.field, view, initial, tracking, state.generator).pose
        state.poses[index] = pose
        tracked = time.perf_counter()
        first_map = len(state.keyframes) == 0
        if has_depth and (first_map or _is_mapped(index, frames, config.mapping.every)):
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
    state.bound_warned = cover_keyframe(
        state.field,
        store.depth(current, device),
        store.intrinsics,
        state.poses[index],
        config.scene,
        state.generator,
        state.bound_warned,
    )
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
    timestamps = sequence_timestamps(sequence)[:done]
    write_tum_trajectory(run.trajectory, timestamps, poses)
    gt = sequence.gt_poses()
    metrics: dict = {
        "frames": done,
        "device": str(device),
        "fpt_s": float(np.sum(state.tracking_time) + np.sum(state.mapping_time)) / max(done, 1),
        "peak_memory_mb": peak_memory_mb(device),
    }
    if gt is not None:
        usable = finite_ate_pairs(poses, gt[:done])
        write_tum_trajectory(run.trajectory_gt, timestamps[usable], gt[:done][usable])
        if usable.sum() >= 3:
            metrics.update(absolute_trajectory_error(poses[usable], gt[:done][usable]).as_cm())
            metrics["ate_frames"] = int(usable.sum())
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
