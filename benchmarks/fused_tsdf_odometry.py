"""KinectFusion-style odometry: what the 7-Scenes reference's own method class scores.

7-Scenes' ground truth comes from KinectFusion (Newcombe et al., ISMAR 2011) run on
the same depth images, so its ATE figures measure how closely a tracker reproduces
that system's trajectory. This runs the same method class with none of ESLAM: every
frame's depth is fused into a voxel TSDF at its tracked pose (Curless and Levoy 1996:
the running average of the projective TSDF,
:func:`eslam.slam.mapping.warm_start.projective_tsdf`), and each new frame is tracked against
that volume from the constant-velocity guess by eslam's SDF tracker (the config's
``tracking.sdf`` settings and border: the Levenberg-Marquardt the ``sdf`` and ``hybrid``
trackers run on the neural map; point-to-implicit residuals where KinectFusion uses
projective point-to-plane ICP against a raycast of the same volume). No neural field,
no mapping, no rendering. A frame the tracker reports as failed keeps the guess and is
not fused, as the run loop does with keyframes; the motion model and that rule are the
front end's own (:func:`~eslam.slam.tracking.trackers.motion_guess`,
:func:`~eslam.slam.tracking.base.judged`).

It writes ``trajectory.txt`` into ``--out`` (readable by ``eslam ate`` and
``benchmarks/trajectory_consistency.py``) and appends ATE RMSE, Sim(3) ATE and scale,
the failed frames and the time per frame to docs/benchmarks.md.

    python benchmarks/fused_tsdf_odometry.py --config configs/sevenscenes/redkitchen.yaml \\
        --data ../shared/data/7scenes-redkitchen --frames 400 --out RUN_FOLDER

With ``--probe SWITCH`` nothing is tracked into the volume: every frame is fused at its
reference pose, and from frame SWITCH on, before the frame is fused, the SDF tracker runs
once from the reference pose (its answer recorded as ``probed.txt``, not used) and the
frame's depth is read against the volume at that pose. This is
``tracking_from_reference.py --probe`` with no ESLAM map: how far the SDF objective
pulls away from the reference on a volume made at the reference's own poses, and the
signed residual r = T s(T q) of the frame's points there (positive: the frame measures
the surface nearer than the frames before it, fused at their reference poses, put it),
per depth half and per ninth of the image. On exact data both are zero to within the
voxels' interpolation; where they are not, the depth and the reference poses disagree,
whatever map a tracker builds. ``--keep K`` keeps only the last K frames in the volume
(each frame K behind is taken back out, BundleFusion's de-integration): whether the
reference agrees with the depth over a short span but not with frames fused long before.

    python benchmarks/fused_tsdf_odometry.py --config configs/sevenscenes/redkitchen.yaml \\
        --data ../shared/data/7scenes-redkitchen --frames 400 --probe 20 [--keep K] --out RUN_FOLDER
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import (
    DEFAULT_DOCS,
    add_device_argument,
    check_device,
    command_line,
    load_average,
    publish,
    section_head,
)
from tracking_from_reference import pull_rows

from eslam.config import ESLAMConfig, SdfTrackerConfig, load_config
from eslam.data import open_sequence
from eslam.data.base import RGBDSequence
from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.geometry.camera import pixels_to_camera_directions, project_points
from eslam.io.trajectory import write_tum_trajectory
from eslam.render.rays import camera_directions
from eslam.slam.mapping.warm_start import projective_tsdf
from eslam.slam.tracking.base import judged
from eslam.slam.tracking.sdf import track_sdf
from eslam.slam.tracking.trackers import motion_guess
from eslam.slam.views import View, make_view
from eslam.types import FieldOutput, Intrinsics

UNSEEN = 1.0
"""TSDF of a voxel no frame has seen: the flat free-space value, so the SDF tracker gives
points there weight 0 (|s| >= max_sdf)."""


@dataclass(frozen=True, eq=False)
class VoxelTsdf:
    """A dense voxel TSDF, queried like the scene field by the SDF tracker.

    Attributes:
        origin: (3,) world position of voxel (0, 0, 0)'s centre, metres.
        voxel: edge length, metres.
        truncation: T, metres; ``values`` are in units of T, in [-1, 1].
        values: (Z, Y, X) running-average TSDF (index [k, j, i] is the voxel at
            origin + voxel * (i, j, k)); :data:`UNSEEN` where ``weights`` is 0.
        weights: (Z, Y, X) number of frames averaged into each voxel.
    """

    origin: torch.Tensor
    voxel: float
    truncation: float
    values: torch.Tensor
    weights: torch.Tensor

    @property
    def bound(self) -> torch.Tensor:
        """(3, 2) box spanned by the voxel centres, [[xmin, xmax], ...], metres."""
        size = torch.tensor(self.values.shape[::-1], dtype=self.origin.dtype) - 1
        far = self.origin + self.voxel * size.to(self.origin.device)
        return torch.stack((self.origin, far), dim=1)

    def query(self, points: torch.Tensor, with_rgb: bool = False) -> FieldOutput:
        """Trilinear TSDF at (N, 3) world points (units of T; differentiable in the
        points), read as the border voxel outside the box. No colour."""
        if with_rgb:
            raise ValueError("a fused TSDF holds no colour: set tracking.sdf.colour_weight: 0")
        low, high = self.bound.unbind(dim=1)
        normalised = 2.0 * (points - low) / (high - low) - 1.0  # grid_sample's (x, y, z)
        sampled = torch.nn.functional.grid_sample(
            self.values[None, None],
            normalised[None, None, None],
            mode="bilinear",  # trilinear on a 5-D input
            padding_mode="border",
            align_corners=True,
        )
        return FieldOutput(sdf=sampled.reshape(-1), rgb=None)


def empty_volume(centre: torch.Tensor, extent: float, voxel: float, truncation: float) -> VoxelTsdf:
    """A cube of side ``extent`` (metres) centred on ``centre`` (3,), every voxel unseen."""
    count = int(np.ceil(extent / voxel)) + 1
    shape = (count, count, count)
    origin = centre - 0.5 * voxel * (count - 1)
    values = torch.full(shape, UNSEEN, dtype=torch.float32, device=centre.device)
    return VoxelTsdf(origin, voxel, truncation, values, torch.zeros_like(values))


def frustum_block(
    volume: VoxelTsdf, depth: torch.Tensor, intrinsics: Intrinsics, c2w: torch.Tensor
) -> tuple[slice, slice, slice] | None:
    """(z, y, x) index slices of the voxels in the box around the camera centre and its
    view frustum out to the frame's farthest depth plus T; None when it misses the volume."""
    far = float(depth.max()) + volume.truncation
    corners = torch.tensor(
        [[0.0, 0.0], [intrinsics.width, 0.0], [0.0, intrinsics.height],
         [intrinsics.width, intrinsics.height]],
        dtype=c2w.dtype, device=c2w.device,
    )  # fmt: skip
    rays = pixels_to_camera_directions(corners, intrinsics)
    camera_points = torch.cat((torch.zeros(1, 3, dtype=c2w.dtype, device=c2w.device), far * rays))
    world = camera_points @ c2w[:3, :3].T + c2w[:3, 3]
    low = torch.floor((world.min(dim=0).values - volume.origin) / volume.voxel).long()
    high = torch.ceil((world.max(dim=0).values - volume.origin) / volume.voxel).long() + 1
    size = torch.tensor(volume.values.shape[::-1], device=low.device)
    low, high = low.clamp(min=0), torch.minimum(high, size)
    if bool((high <= low).any()):
        return None
    x, y, z = (slice(int(a), int(b)) for a, b in zip(low, high, strict=True))
    return z, y, x


def fuse(
    volume: VoxelTsdf,
    depth: torch.Tensor,
    intrinsics: Intrinsics,
    c2w: torch.Tensor,
    remove: bool = False,
) -> None:
    """Average one depth image (H, W; metres, 0 = invalid) seen from ``c2w`` into
    ``volume`` in place (Curless and Levoy 1996; KinectFusion's eq. 11-12 with weight 1),
    or with ``remove`` take an image fused earlier back out.

    Each voxel centre p projects to its nearest pixel with depth D; with z its depth in
    the camera, the observation is s = clip((D - z) / T, -1, 1) where D > 0 and
    D - z >= -T (voxels further behind the surface are not observed), and the voxel's
    value becomes (W s_old + s) / (W + 1), W <- W + 1. Removing (BundleFusion's
    de-integration, Dai et al. 2017) inverts it: (W s_old - s) / (W - 1), W <- W - 1,
    and a voxel left with no observation reads :data:`UNSEEN` again."""
    block = frustum_block(volume, depth, intrinsics, c2w)
    if block is None:
        return
    values, weights = volume.values[block], volume.weights[block]  # views
    axes = [torch.arange(b.start, b.stop, device=depth.device) for b in block]
    k, j, i = torch.meshgrid(*axes, indexing="ij")
    centres = volume.origin + volume.voxel * torch.stack((i, j, k), dim=-1).to(depth.dtype)
    uv, z = project_points(centres, intrinsics, c2w.to(depth.dtype))
    column, row = torch.round(uv[..., 0]).long(), torch.round(uv[..., 1]).long()
    inside = (z > 0) & (column >= 0) & (column < intrinsics.width)
    inside &= (row >= 0) & (row < intrinsics.height)
    measured = torch.where(
        inside,
        depth[row.clamp(0, intrinsics.height - 1), column.clamp(0, intrinsics.width - 1)],
        torch.zeros_like(z),
    )
    observed = inside & (measured > 0) & (measured - z >= -volume.truncation)
    observation = projective_tsdf(z, measured, volume.truncation)
    sign = -1.0 if remove else 1.0
    total = weights + sign * observed.to(weights.dtype)
    average = (values * weights + sign * observation) / total.clamp_min(1.0)
    average = torch.where(total > 0, average, torch.full_like(average, UNSEEN))
    values.copy_(torch.where(observed, average, values))
    weights.copy_(total)


@dataclass(frozen=True)
class Odometry:
    """A fused-TSDF odometry run: camera-to-world poses (N, 4, 4) float64, the frames
    whose tracking failed, and the seconds spent per frame (tracking plus fusion)."""

    poses: np.ndarray
    failed: list[int]
    seconds_per_frame: float


@dataclass(frozen=True)
class Setting:
    """What an odometry run and a probe share: the config, the sequence, its camera's
    ray directions, and the volume with the first frame fused at ``start``."""

    config: ESLAMConfig
    sequence: RGBDSequence
    directions: torch.Tensor
    volume: VoxelTsdf
    start: torch.Tensor


def setting(
    config_path: Path,
    data: Path,
    frames: int,
    voxel: float,
    extent: float,
    device: torch.device,
    overrides: tuple[str, ...],
) -> Setting:
    """Open ``data`` with the config (``overrides`` applied) and fuse its first frame at
    its reference pose (the identity without one) into a cube of side ``extent``
    centred ``extent / 2 - 1`` m in front of that camera."""
    given = [f"data.path={data}", "data.register_colour=false", *overrides]
    config = load_config(config_path, given)
    sequence = open_sequence(config.data)
    if frames < 2 or frames > len(sequence):
        raise SystemExit(f"{data}: --frames must be in 2..{len(sequence)}, got {frames}")
    first = sequence[0]
    start = torch.as_tensor(
        first.pose_gt if first.pose_gt is not None else np.eye(4),
        dtype=torch.float32,
        device=device,
    )
    forward = start[:3, 2] * (0.5 * extent - 1.0)
    volume = empty_volume(start[:3, 3] + forward, extent, voxel, config.field.truncation)
    fuse(volume, torch.as_tensor(first.depth, device=device), sequence.intrinsics, start)
    directions = camera_directions(sequence.intrinsics, device)
    return Setting(config, sequence, directions, volume, start)


def frame_view(setting: Setting, index: int) -> tuple[View, torch.Tensor]:
    """Frame ``index`` as the tracker sees it (the config's border) and its depth (H, W)."""
    frame = setting.sequence[index]
    device = setting.directions.device
    depth = torch.as_tensor(frame.depth, device=device)
    rgb = torch.as_tensor(frame.rgb, device=device).float() / 255.0
    view = make_view(rgb, depth, setting.directions, border=setting.config.tracking.border)
    return view, depth


def fused_tsdf_odometry(
    config_path: Path,
    data: Path,
    frames: int,
    voxel: float,
    extent: float,
    device: torch.device,
    seed: int = 0,
    overrides: tuple[str, ...] = (),
) -> tuple[Odometry, np.ndarray | None, np.ndarray]:
    """Track the first ``frames`` frames of ``data`` against a TSDF fused from them
    (module doc); the volume as :func:`setting` makes it; ``overrides`` (``key=value``)
    apply to the config. Returns the odometry, the ground truth poses (or None) and the
    timestamps."""
    run = setting(config_path, data, frames, voxel, extent, device, overrides)
    generator = torch.Generator(device=device).manual_seed(seed)
    poses = [run.start]
    failed = []
    begin = time.perf_counter()
    for index in range(1, frames):
        view, depth = frame_view(run, index)
        after_failure = bool(failed) and failed[-1] == index - 1
        velocity = run.config.tracking.constant_velocity
        guess = motion_guess(torch.stack(poses), velocity, after_failure)
        result = track_sdf(run.volume, view, guess, run.config.tracking.sdf, generator)
        pose, quality = judged(result, guess)
        poses.append(pose)
        if quality is not None and quality.failed:
            failed.append(index)
            continue
        fuse(run.volume, depth, run.sequence.intrinsics, pose)
    seconds = (time.perf_counter() - begin) / (frames - 1)
    estimate = torch.stack(poses).double().cpu().numpy()
    truth = run.sequence.gt_poses()
    timestamps = run.sequence.timestamps()[:frames]
    odometry = Odometry(estimate, failed, seconds)
    return odometry, (truth[:frames] if truth is not None else None), timestamps


MIN_REGION_POINTS = 50
"""Points in the band an image ninth needs for its median residual (else NaN)."""


@dataclass(frozen=True)
class FrameResidual:
    """A frame's signed residuals r = T s(T q) at a pose (metres; positive: the point
    lies in front of the volume's surface), medians over its sampleable pixels whose
    |s| is below the tracker's ``max_sdf``.

    Attributes:
        median: over all of them.
        near: over those nearer than their median depth.
        far: over the others.
        ninths: (3, 3) per ninth of the image, rows top to bottom (NaN with fewer than
            :data:`MIN_REGION_POINTS`).
    """

    median: float
    near: float
    far: float
    ninths: np.ndarray


def frame_residual(
    volume: VoxelTsdf, view: View, pose: torch.Tensor, width: int, height: int, max_sdf: float
) -> FrameResidual:
    """The signed residuals of every sampleable pixel of ``view`` (``width`` x ``height``)
    at ``pose`` against ``volume`` (:class:`FrameResidual`)."""
    pixels = torch.nonzero(torch.diff(view.cumulative, prepend=view.cumulative[:1] * 0))[:, 0]
    camera = view.directions[pixels] * view.depth[pixels, None]
    world = camera @ pose[:3, :3].T + pose[:3, 3]
    with torch.no_grad():
        sdf = volume.query(world).sdf
    band = sdf.abs() < max_sdf
    residual = (volume.truncation * sdf)[band]
    depth, pixels = camera[band, 2], pixels[band]
    if len(residual) == 0:
        nan = float("nan")
        return FrameResidual(nan, nan, nan, np.full((3, 3), np.nan))
    near = depth < depth.median()
    column, row = pixels % width, pixels // width
    ninth = (3 * row // height) * 3 + 3 * column // width
    ninths = [
        float(residual[ninth == k].median())
        if int((ninth == k).sum()) >= MIN_REGION_POINTS
        else float("nan")
        for k in range(9)
    ]
    far = residual[~near]
    return FrameResidual(
        median=float(residual.median()),
        near=float(residual[near].median()) if bool(near.any()) else float("nan"),
        far=float(far.median()) if len(far) else float("nan"),
        ninths=np.array(ninths).reshape(3, 3),
    )


@dataclass(frozen=True)
class ReferenceProbe:
    """What :func:`probe_reference` measured from frame ``switch`` on.

    Attributes:
        probed: (N - switch, 4, 4) float64: the SDF tracker's answer from each
            frame's reference pose.
        residuals: the frames' :class:`FrameResidual` at their reference poses.
        reference: (N, 4, 4) float64 reference poses of frames 0..N-1.
        timestamps: (N,) their timestamps.
    """

    probed: np.ndarray
    residuals: list[FrameResidual]
    reference: np.ndarray
    timestamps: np.ndarray


def probe_reference(
    config_path: Path,
    data: Path,
    switch: int,
    frames: int,
    voxel: float,
    extent: float,
    device: torch.device,
    seed: int = 0,
    overrides: tuple[str, ...] = (),
    keep: int | None = None,
) -> ReferenceProbe:
    """Fuse frames 0..``frames``-1 at their reference poses; from ``switch`` on, before
    each is fused, track it from its reference pose and read its residuals there
    (module doc, ``--probe``). With ``keep`` K the volume holds the last K frames only
    (frame i - K is taken out when frame i is fused): the tracker sees the reference's
    poses over a span of K frames instead of since frame 0."""
    run = setting(config_path, data, frames, voxel, extent, device, overrides)
    if not 1 <= switch < frames:
        raise SystemExit(f"{data}: need 1 <= --probe < --frames, got {switch} and {frames}")
    if keep is not None and keep < 1:
        raise SystemExit(f"--keep must be >= 1, got {keep}")
    truth = run.sequence.gt_poses()
    if truth is None or not np.isfinite(truth[:frames]).all():
        raise SystemExit(f"{data}: --probe needs a ground-truth pose for each of {frames} frames")
    reference = torch.as_tensor(truth[:frames], dtype=torch.float32, device=device)
    settings: SdfTrackerConfig = run.config.tracking.sdf
    intrinsics = run.sequence.intrinsics
    generator = torch.Generator(device=device).manual_seed(seed)
    answers, residuals = [], []
    # with keep: the depth images in the volume, oldest first (read once, taken out later)
    held = deque([torch.as_tensor(run.sequence[0].depth, device=device)] if keep else [])
    for index in range(1, frames):
        view, depth = frame_view(run, index)
        pose = reference[index]
        if index >= switch:
            answers.append(track_sdf(run.volume, view, pose, settings, generator).pose)
            residuals.append(
                frame_residual(
                    run.volume, view, pose, intrinsics.width, intrinsics.height, settings.max_sdf
                )
            )
        fuse(run.volume, depth, intrinsics, pose)
        if keep is not None:
            held.append(depth)
            if len(held) > keep:  # frame index - keep leaves the volume
                gone = held.popleft()
                fuse(run.volume, gone, intrinsics, reference[index - keep], remove=True)
    return ReferenceProbe(
        probed=torch.stack(answers).double().cpu().numpy(),
        residuals=residuals,
        reference=truth[:frames],
        timestamps=run.sequence.timestamps()[:frames],
    )


def nan_median(values: np.ndarray, axis: int | None = None) -> np.ndarray:
    """np.nanmedian, NaN (without a warning) where every value is NaN."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # "All-NaN slice encountered"
        return np.nanmedian(values, axis=axis)


def residual_rows(residuals: list[FrameResidual], switch: int, segment: int) -> list[str]:
    """One markdown row per ``segment`` frames from ``switch`` (``residuals[k]`` is frame
    ``switch + k``'s): the medians over the segment's frames of each frame's median
    residual, near half and far half (mm), and of each ninth (mm; rows top to bottom,
    ``/`` between rows)."""
    rows = []
    for start in range(0, len(residuals), segment):
        chunk = residuals[start : start + segment]
        first, last = switch + start, switch + start + len(chunk) - 1

        def median_mm(values: list[float]) -> str:
            return f"{1000 * nan_median(np.array(values)):+.1f}"

        ninths = 1000 * nan_median(np.stack([r.ninths for r in chunk]), axis=0)
        image = " / ".join(" ".join(f"{value:+.1f}" for value in row) for row in ninths)
        rows.append(
            f"| {first}-{last} | {median_mm([r.median for r in chunk])} "
            f"| {median_mm([r.near for r in chunk])} | {median_mm([r.far for r in chunk])} "
            f"| {image} |"
        )
    return rows


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", type=Path, required=True)
    parser.add_argument("--data", type=Path, required=True, help="the sequence folder")
    parser.add_argument("--frames", type=int, required=True)
    parser.add_argument("--out", type=Path, required=True, help="folder for trajectory.txt")
    parser.add_argument("--voxel", type=float, default=0.02, help="metres (0.02)")
    parser.add_argument("--extent", type=float, default=6.0, help="cube side, metres (6)")
    parser.add_argument("--seed", type=int, default=0, help="of the SDF tracker's points")
    parser.add_argument(
        "--probe",
        type=int,
        metavar="SWITCH",
        help="fuse at the reference poses; probe the tracker from them from frame SWITCH on",
    )
    parser.add_argument("--segment", type=int, default=50, help="frames per probe row (50)")
    parser.add_argument(
        "--keep", type=int, help="--probe: the volume holds the last KEEP frames only"
    )
    parser.add_argument("--threads", type=int, default=0, help="0 = torch's default")
    add_device_argument(parser)
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS)
    parser.add_argument("--no-append", action="store_true")
    parser.add_argument("--note", default="")
    parser.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    args = parser.parse_intermixed_args(argv)  # overrides may come before options
    if args.voxel <= 0 or args.extent <= 2 * args.voxel or args.threads < 0:
        parser.error("--voxel must be > 0, --extent > 2 voxels, --threads >= 0")
    if args.segment < 1:
        parser.error("--segment must be >= 1")
    if args.keep is not None and (args.keep < 1 or args.probe is None):
        parser.error("--keep must be >= 1 and goes with --probe")
    check_device(parser, args)
    return args


def odometry_table(args: argparse.Namespace, device: torch.device) -> list[str]:
    """Run the odometry, write its trajectory and return its section's table."""
    odometry, truth, timestamps = fused_tsdf_odometry(
        args.config,
        args.data,
        args.frames,
        args.voxel,
        args.extent,
        device,
        args.seed,
        tuple(args.overrides),
    )
    args.out.mkdir(parents=True, exist_ok=True)
    write_tum_trajectory(args.out / "trajectory.txt", timestamps, odometry.poses)
    lines = [
        "| frames | ATE RMSE | Sim(3) ATE | Sim(3) scale | failed frames | s/frame |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    if truth is None:
        ate = sim3 = scale = "n/a (no ground truth)"
    else:
        rigid = absolute_trajectory_error(odometry.poses, truth)
        similar = absolute_trajectory_error(odometry.poses, truth, with_scale=True)
        ate, sim3 = f"{100 * rigid.rmse:.2f} cm", f"{100 * similar.rmse:.2f} cm"
        scale = f"{similar.alignment.scale:.4f}"
    lines.append(
        f"| {args.frames} | {ate} | {sim3} | {scale} | {len(odometry.failed)} "
        f"| {odometry.seconds_per_frame:.2f} |"
    )
    return lines


def probe_tables(args: argparse.Namespace, device: torch.device) -> list[str]:
    """Run the probe, write the tracker's answers and return its section's tables."""
    switch = args.probe
    probe = probe_reference(
        args.config,
        args.data,
        switch,
        args.frames,
        args.voxel,
        args.extent,
        device,
        args.seed,
        tuple(args.overrides),
        args.keep,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    write_tum_trajectory(args.out / "probed.txt", probe.timestamps[switch:], probe.probed)
    held = "every frame so far" if args.keep is None else f"the last {args.keep} frames only"
    return [
        f"- every frame fused at its reference pose (the volume holds {held}); from frame "
        f"{switch} the SDF tracker runs once per frame from the reference pose before the "
        "frame is fused, its answer recorded, not used",
        "",
        "| frames | reference step, median (mm) | pull, median (mm) | pull, largest (mm) "
        "| pull along the motion / step | rotation pull, median (deg) |",
        "|---|---:|---:|---:|---:|---:|",
        *pull_rows(probe.probed, probe.reference, switch, args.segment),
        "",
        "Signed residual T s(T q) of each frame's points at its reference pose against the "
        "frames fused before it (positive: nearer than the volume's surface), medians of "
        "the per-frame medians (mm):",
        "",
        "| frames | all points | nearer half | farther half | by ninth of the image, "
        "rows top to bottom |",
        "|---|---:|---:|---:|---|",
        *residual_rows(probe.residuals, switch, args.segment),
    ]


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    load_start = load_average()
    tables = probe_tables(args, device) if args.probe is not None else odometry_table(args, device)
    lines = section_head(
        "fused_tsdf_odometry",
        device,
        (load_start, load_average()),
        command_line("benchmarks/fused_tsdf_odometry.py", argv),
        f"{args.data}, frames 0-{args.frames - 1}",
        ("overrides", args.overrides),
        args.note or None,
    )
    lines += [
        f"- voxel TSDF: {args.voxel:g} m voxels, a {args.extent:g} m cube, truncation "
        "from the config's field.truncation; tracker: the config's tracking.sdf and border",
        "",
        *tables,
        "",
    ]
    publish("\n".join(lines), args.docs, args.no_append)


if __name__ == "__main__":
    main()
