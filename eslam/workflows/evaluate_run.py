"""`eslam eval RUN_DIR`: score a finished run (docs/method.md section 6), write report.md.

1. ATE of trajectory.txt against trajectory_gt.txt (all statistics, SE(3) Umeyama).
2. With a ground-truth mesh: cull the run's mesh (estimated poses) and the GT mesh
   (ground-truth poses) with the same protocol over the sequence's frames, write
   mesh_culled.ply, then accuracy / completion / completion ratio / precision /
   recall / F1 and depth L1. The reconstruction is compared in the run's world frame,
   unaligned, as the papers do (frame 0 starts at its ground-truth pose).
3. metrics.json gains the new keys (rewritten atomically); report.md gets the table,
   the evaluation settings and two plots (trajectory top/side views, per-frame error).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from eslam.config import ESLAMConfig, load_config
from eslam.data import RGBDSequence, open_sequence, sequence_timestamps
from eslam.errors import ConfigError, InputError
from eslam.evaluate.depth_l1 import DepthL1Options, depth_l1
from eslam.evaluate.reconstruction import (
    RELEASE_SAMPLES,
    ReconstructionOptions,
    evaluate_reconstruction,
)
from eslam.evaluate.report import write_report
from eslam.evaluate.trajectory import ATEResult, absolute_trajectory_error, associate_timestamps
from eslam.io.mesh_files import read_mesh, read_mesh_ply, write_mesh_ply
from eslam.io.run_dir import RunDirectory, write_json
from eslam.io.trajectory import read_trajectory
from eslam.mesh.cull import CullCameras, CullOptions, cull_mesh
from eslam.slam.run.folder import check_same_input
from eslam.types import TriangleMesh
from eslam.viz.plots import plot_trajectories, plot_translation_error
from eslam.workflows.progress import StageProgress


@dataclass(frozen=True)
class EvaluationOptions:
    """How ``eslam eval`` scores a run.

    Attributes:
        gt_mesh: ground-truth mesh in the world frame of the poses; None = ATE only.
        protocol: culling: "eslam" (frustum + occlusion, the paper) or "nice" (frustum).
        samples: surface samples per mesh (the ESLAM protocol: 450,000).
        exact: point-to-surface distances instead of sample-to-sample.
        depth_l1_views: virtual views of the depth L1 (the release: 1000); 0 = skip.
        seed: seed of the samples and of the virtual views.
        max_unobserved_fraction: a virtual view with more of its pixels seeing space no
            frame observed is redrawn (the release: 0); the rest are not scored.
        cull_every: cull with every k-th frame of the run (1 = all, as the paper).
        max_edge: subdivide longer mesh edges (metres) before culling; None = no.
        device: where culling projects points.
        data: the run's sequence where it moved (its fingerprint must still match the
            run's input.json); None = config.yaml's data.path.
        title: report.md's title; None = :func:`report_title` of the run folder.
        progress: a bar per stage on stderr (culling, distances, depth L1: minutes).
    """

    gt_mesh: Path | None = None
    protocol: Literal["eslam", "nice"] = "eslam"
    samples: int = RELEASE_SAMPLES
    exact: bool = False
    depth_l1_views: int = 1000
    seed: int = 0
    max_unobserved_fraction: float = 0.0
    cull_every: int = 1
    max_edge: float | None = None
    device: str = "cpu"
    data: Path | None = None
    title: str | None = None
    progress: bool = False

    def __post_init__(self) -> None:
        """Refuse counts that would score nothing (or crash deep in the metrics)."""
        for name, least in (("samples", 1), ("cull_every", 1), ("depth_l1_views", 0)):
            value = getattr(self, name)
            if value < least:
                flag = "--views" if name == "depth_l1_views" else f"--{name.replace('_', '-')}"
                raise ConfigError(f"{flag} must be >= {least}, got {value}")
        if not 0.0 <= self.max_unobserved_fraction <= 1.0:
            raise ConfigError(
                f"--max-unobserved must be in [0, 1], got {self.max_unobserved_fraction}"
            )


EVALUATION_KEYS = (
    "ate_rmse_cm",
    "ate_mean_cm",
    "ate_median_cm",
    "ate_max_cm",
    "ate_frames",
    "accuracy_cm",
    "completion_cm",
    "completion_ratio_pct",
    "precision_pct",
    "recall_pct",
    "f1_pct",
    "depth_l1_cm",
)
"""metrics.json keys an evaluation (re)computes: stale values are dropped first."""

TRAJECTORY_PLOT = "trajectory.png"
ERROR_PLOT = "translation_error.png"


def evaluate_run(run_dir: str | Path, options: EvaluationOptions) -> dict[str, object]:
    """Score the run in ``run_dir``; return the updated metrics (also in metrics.json).

    Raises:
        InputError: not a finished run folder, a missing mesh, or an unreadable GT mesh.
    """
    run = RunDirectory(Path(run_dir))
    if not run.config.is_file():
        raise InputError(run.config, "not found: not a run folder", "run `eslam run` first")
    if not run.trajectory.is_file():
        raise InputError(
            run.trajectory,
            "not found: the run saved no frame yet",
            f"continue it with `eslam resume {run.root}`",
        )
    config = load_config(run.config)
    metrics: dict[str, object] = {}
    if run.metrics.is_file():  # a run killed before its first checkpoint's metrics has none
        metrics = json.loads(run.metrics.read_text(encoding="utf-8"))
    metrics = {k: v for k, v in metrics.items() if k not in EVALUATION_KEYS}
    settings: list[str] = []
    images: list[tuple[str, str]] = []
    timestamps, estimated = read_trajectory(run.trajectory, allow_missing=True)
    progress = StageProgress(options.progress)
    if run.trajectory_gt.is_file():
        with progress.stage("ATE and plots"):
            ate = _trajectory_error(run, timestamps, estimated)
        metrics.update({k: v for k, v in ate.as_dict().items() if k.startswith("ate_")})
        metrics["ate_frames"] = ate.pairs
        settings.append(
            f"ATE: SE(3) Umeyama alignment of {ate.pairs} camera positions "
            "(trajectory.txt against trajectory_gt.txt, matched by timestamp)"
        )
        images += [("Trajectory (top and side views)", TRAJECTORY_PLOT)]
        images += [("Per-frame translation error", ERROR_PLOT)]
    if options.gt_mesh is not None:
        metrics.update(
            _reconstruction(run, config, (timestamps, estimated), options, (settings, progress))
        )
    write_json(run.metrics, metrics)
    title = options.title or report_title(run.root)
    write_report(run.root / "report.md", title, metrics, settings, images)
    return metrics


def report_title(run_dir: Path) -> str:
    """report.md's default title: the run folder as the user named it (``runs/room0``),
    so two reports are told apart by more than a folder name like ``run``."""
    return f"Evaluation of run {run_dir}"


def _trajectory_error(
    run: RunDirectory, timestamps: np.ndarray, estimated: np.ndarray
) -> ATEResult:
    if len(timestamps) < 3:  # a run stopped after a frame or two: not a broken folder
        raise InputError(
            run.trajectory,
            f"holds {len(timestamps)} frames, and the ATE needs at least 3",
            f"continue the run with `eslam resume {run.root}`, then evaluate it",
        )
    gt_times, gt = read_trajectory(run.trajectory_gt, ground_truth=True, allow_missing=True)
    est_index, gt_index = associate_timestamps(timestamps, gt_times, 1e-6)
    usable = np.isfinite(estimated[est_index]).all(axis=(1, 2)) & np.isfinite(gt[gt_index]).all(
        axis=(1, 2)
    )
    est_index, gt_index = est_index[usable], gt_index[usable]
    if len(est_index) < 3:
        raise InputError(
            run.trajectory_gt,
            f"only {len(est_index)} frames match trajectory.txt by timestamp",
            "was the run folder assembled from different runs?",
        )
    ate = absolute_trajectory_error(estimated[est_index], gt[gt_index])
    aligned = ate.alignment.apply(estimated[est_index, :3, 3])
    plot_trajectories(gt[gt_index, :3, 3], aligned, run.root / TRAJECTORY_PLOT)
    plot_translation_error(timestamps[est_index], ate.errors, run.root / ERROR_PLOT)
    return ate


def sequence_frames(
    timestamps: np.ndarray, sequence: RGBDSequence
) -> tuple[np.ndarray, np.ndarray]:
    """Rows of a run's trajectory and the frames of ``sequence`` they estimate, matched by
    timestamp: frame i is row i for a run that took every frame, but a real-time run
    processed only some (the others were dropped).

    Returns:
        (M,) row indices and (M,) sequence frame indices, in trajectory order.
    """
    return associate_timestamps(timestamps, sequence_timestamps(sequence), 1e-6)


def _reconstruction(
    run: RunDirectory,
    config: ESLAMConfig,
    trajectory: tuple[np.ndarray, np.ndarray],
    options: EvaluationOptions,
    notes: tuple[list[str], StageProgress],
) -> dict[str, object]:
    """The mesh metrics of the run whose ``trajectory`` is (timestamps, poses); appends how
    they were measured to ``notes``' settings and shows each stage on ``notes``' progress."""
    settings, progress = notes
    if not run.mesh.is_file():
        raise InputError(run.mesh, "not found", f"extract it with `eslam mesh {run.root}`")
    reconstruction = read_mesh_ply(run.mesh)
    ground_truth = read_mesh(options.gt_mesh)
    sequence = _run_sequence(run, config, options.data)
    rows, frames = sequence_frames(trajectory[0], sequence)
    rows, frames = rows[:: options.cull_every], frames[:: options.cull_every]
    cull = CullOptions(config.field.truncation, options.max_edge, options.device)
    gt_poses = sequence.gt_poses()
    if gt_poses is None:
        raise InputError(
            sequence.root, "has no ground-truth poses to cull the GT mesh with", "use --protocol"
        )
    estimated = trajectory[1][rows]
    culls = (
        ("cull mesh.ply", estimated, reconstruction),
        ("cull GT mesh", gt_poses[frames], ground_truth),
    )
    culled = []
    for name, poses, mesh in culls:
        with progress.stage(name, len(frames), "frame") as advance:
            culled.append(
                _culled(mesh, sequence, poses, frames, CullRequest(options, cull, advance))
            )
    rec_culled, gt_culled = culled
    write_mesh_ply(run.mesh_culled, rec_culled)
    recon = ReconstructionOptions(samples=options.samples, seed=options.seed, exact=options.exact)
    with progress.stage("accuracy and completion"):
        result = evaluate_reconstruction(rec_culled, gt_culled, recon).as_dict()
    metrics: dict[str, object] = {k: v for k, v in result.items() if k not in ("samples", "exact")}
    mode = "exact point-to-surface" if options.exact else "sample-to-sample (KD-tree)"
    settings.append(
        f"reconstruction: {options.protocol} culling of both meshes over {len(frames)} frames "
        f"(T = {config.field.truncation} m), {options.samples:,} seeded samples per mesh "
        f"(seed {options.seed}), {mode} distances; GT mesh {options.gt_mesh}"
    )
    if options.depth_l1_views > 0:
        views = DepthL1Options(views=options.depth_l1_views, seed=options.seed)
        pixels = int(options.max_unobserved_fraction * views.width * views.height)
        views = dataclasses.replace(views, max_unobserved_pixels=pixels)
        with progress.stage("depth L1", views.views, "view") as advance:
            depth = depth_l1(rec_culled, gt_culled, views, ground_truth, advance)
        metrics["depth_l1_cm"] = depth.depth_l1_cm
        settings.append(
            f"depth L1: {depth.views_used} random virtual views ({views.width}x{views.height}, "
            f"focal {views.focal:g}), {depth.views_rejected} drawn views rejected "
            f"(more than {pixels} pixels of unobserved space, or no common depth)"
        )
    return metrics


def _run_sequence(run: RunDirectory, config: ESLAMConfig, data: Path | None) -> RGBDSequence:
    """The run's sequence (at ``data`` when given), checked to be the input it ran on."""
    if data is not None:
        config = dataclasses.replace(
            config, data=dataclasses.replace(config.data, path=str(Path(data).absolute()))
        )
    sequence = open_sequence(config.data)
    check_same_input(run, sequence)
    return sequence


@dataclass(frozen=True)
class CullRequest:
    """How to cull one mesh: the evaluation's options, the culling settings, and the
    progress callback (frames read so far)."""

    options: EvaluationOptions
    cull: CullOptions
    advance: Callable[[int], None]


def _culled(
    mesh: TriangleMesh,
    sequence: RGBDSequence,
    poses: np.ndarray,
    frames: np.ndarray,
    request: CullRequest,
) -> TriangleMesh:
    """``mesh`` culled by the cameras ``poses`` (F, 4, 4) of the sequence's ``frames`` (F,)."""
    finite = np.isfinite(poses).all(axis=(1, 2))
    usable = frames[finite]
    protocol = request.options.protocol
    depths = _depths(sequence, usable, request.advance) if protocol == "eslam" else None
    cameras = CullCameras(poses[finite], sequence.intrinsics, depths)
    culled = cull_mesh(mesh, cameras, protocol, request.cull)
    request.advance(len(frames))  # also the frames left out and those without depth read
    return culled


def _depths(
    sequence: RGBDSequence, frames: np.ndarray, advance: Callable[[int], None]
) -> Iterator[np.ndarray]:
    """The depth maps of ``frames``, read one at a time (culling streams them)."""
    for done, index in enumerate(frames):
        yield sequence[int(index)].depth
        advance(done + 1)
