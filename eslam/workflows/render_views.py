"""`eslam render`: colour and depth views of a run's saved map, without input depth.

Views are rendered from RUN_DIR/map.pt alone (:func:`eslam.render.surface.render_novel_view`:
the paper's samples for rays without depth; colour volume-rendered, depth where the
TSDF crosses zero), along the run's own estimated trajectory by default, or along a
trajectory file, or on an orbit around the scene (:func:`eslam.render.orbit.orbit_poses`),
with the run's camera (intrinsics and image size as the run used them; ``size``
rescales them). The output folder holds ``colour/NNNNNN.png`` (8-bit RGB),
``depth/NNNNNN.png`` (16-bit, millimetres, 0 = nothing hit), NNNNNN the pose's
position in the trajectory, and ``video.mp4`` (colour beside a colour-mapped depth
panel) when imageio-ffmpeg is installed. The folder is built under a temporary name and
published whole (:func:`eslam.atomic.atomic_directory`). See docs/render.md.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from eslam.atomic import atomic_directory
from eslam.config.device import resolve_device
from eslam.errors import InputError
from eslam.io.saved_run import load_run
from eslam.io.trajectory import read_trajectory
from eslam.render.orbit import orbit_poses
from eslam.render.renderer import DEFAULT_CHUNK
from eslam.render.surface import render_novel_view
from eslam.slam.state import load_state
from eslam.viz.depth_images import depth_colours, depth_millimetres
from eslam.workflows.progress import StageProgress

DEFAULT_ORBIT_VIEWS = 120
"""Views on an orbit when ``--orbit`` gives no count (4 s of video at 30 frames/s)."""
VIDEO_NAME = "video.mp4"
"""The video's file name in the output folder."""
DEPTH_RANGE_PERCENTILES = (1.0, 99.0)
"""The video's depth colours span these percentiles of the hit depths (the lowest and
highest over all views), one range for the whole video so colours do not flicker."""
NO_FFMPEG = 'no video: imageio-ffmpeg is not installed (pip install "eslam[viewer]")'
"""What the result says instead of a video path when ffmpeg is not available."""


@dataclass(frozen=True)
class RenderOptions:
    """What ``eslam render`` renders and where.

    Attributes:
        trajectory: poses to render (any format :func:`eslam.io.trajectory.read_trajectory`
            reads: TUM, Replica traj.txt, a run folder); None = the run's estimate.
        orbit: render this many views on an orbit instead (None = no orbit).
        size: (width, height) of the views; None = the run's image size.
        out: output folder; None = RUN_DIR/render.
        device: where the field is evaluated (cpu, cuda, cuda:N, mps, auto).
        overwrite: replace an existing non-empty output folder (once the new one is done).
        video: write video.mp4 when imageio-ffmpeg is installed.
        fps: the video's frame rate.
        chunk: rays rendered at once (bounds memory).
        progress: show a progress bar.
    """

    trajectory: Path | None = None
    orbit: int | None = None
    size: tuple[int, int] | None = None
    out: Path | None = None
    device: str = "cpu"
    overwrite: bool = False
    video: bool = True
    fps: float = 30.0
    chunk: int = DEFAULT_CHUNK
    progress: bool = True


@dataclass(frozen=True)
class RenderResult:
    """What :func:`render_run` wrote.

    Attributes:
        out: the output folder.
        views: views written.
        skipped: poses left out because they are missing (NaN) in the trajectory.
        size: (width, height) of the views.
        video: the video file, or None.
        video_note: why there is no video (None when there is one).
        seconds: wall time of the rendering.
    """

    out: Path
    views: int
    skipped: int
    size: tuple[int, int]
    video: Path | None
    video_note: str | None
    seconds: float


def _poses(options: RenderOptions, run_poses: np.ndarray, bound: np.ndarray) -> np.ndarray:
    if options.trajectory is not None and options.orbit is not None:
        raise InputError(options.trajectory, "given with an orbit", "pass one of the two")
    if options.trajectory is not None:
        return read_trajectory(options.trajectory, allow_missing=True)[1]
    if options.orbit is not None:
        return orbit_poses(bound, run_poses, options.orbit)
    return run_poses


def _check_out(out: Path, run_root: Path) -> None:
    """Refuse an output folder that would replace the run folder or one above it."""
    resolved, run = out.resolve(), run_root.resolve()
    if resolved == run or resolved in run.parents:
        raise InputError(out, "would replace the run folder", "pass --out a folder of its own")


def render_run(run_dir: str | Path, options: RenderOptions = RenderOptions()) -> RenderResult:
    """Render views of the run in ``run_dir`` from its map (module doc).

    Raises:
        InputError: not a run folder, no map.pt or an empty map, an unreadable
            trajectory file, or an output folder that exists (without ``overwrite``).
        ConfigError: an unknown or unavailable device.
    """
    run = load_run(run_dir)
    if run.map_path is None:
        raise InputError(
            run.root / "map.pt", "not found: the run saved no map", "run or resume it first"
        )
    device = resolve_device(options.device)
    state = load_state(run.map_path, run.config, device)
    field = state.field
    if field is None:
        raise InputError(run.map_path, "holds no map yet (no frame with depth)", "run longer")
    intrinsics = state.keyframes.intrinsics
    if options.size is not None:
        intrinsics = intrinsics.scaled(*options.size)
    bound = field.bound.detach().cpu().double().numpy()
    poses = _poses(options, run.poses, bound)
    out = Path(options.out) if options.out is not None else run.root / "render"
    _check_out(out, run.root)
    if out.is_dir() and any(out.iterdir()) and not options.overwrite:
        raise InputError(out, "already exists", "pass --overwrite to replace it, or another --out")
    started = time.perf_counter()
    written: list[str] = []
    low, high = np.inf, -np.inf
    with atomic_directory(out, overwrite=options.overwrite) as staging:
        for folder in ("colour", "depth"):
            (staging / folder).mkdir()
        with StageProgress(options.progress).stage("rendering", len(poses), "view") as advance:
            for position, pose in enumerate(poses):
                if np.isfinite(pose).all():
                    c2w = torch.from_numpy(pose).to(device=device, dtype=torch.float32)
                    depth, rgb = render_novel_view(
                        field, intrinsics, c2w, run.config.render, options.chunk
                    )
                    depth_np = depth.cpu().numpy()
                    name = f"{position:06d}.png"
                    colour = np.round(255.0 * rgb.clamp(0.0, 1.0).cpu().numpy()).astype(np.uint8)
                    Image.fromarray(colour).save(staging / "colour" / name)
                    Image.fromarray(depth_millimetres(depth_np)).save(staging / "depth" / name)
                    written.append(name)
                    hits = depth_np[depth_np > 0]
                    if len(hits):
                        lo, hi = np.percentile(hits, DEPTH_RANGE_PERCENTILES)
                        low, high = min(low, float(lo)), max(high, float(hi))
                advance(position + 1)
        video, note = None, None
        if not options.video:
            note = "no video: not asked for"
        elif not written:
            note = "no video: no view was rendered"
        else:
            try:
                import imageio_ffmpeg
            except ImportError:
                note = NO_FFMPEG
            else:
                if not high > low:
                    low, high = 0.0, max(high, 1.0)
                write_video(imageio_ffmpeg, staging, written, (low, high), options.fps)
                video = out / VIDEO_NAME
    return RenderResult(
        out=out,
        views=len(written),
        skipped=len(poses) - len(written),
        size=intrinsics.size,
        video=video,
        video_note=note,
        seconds=time.perf_counter() - started,
    )


def video_panel(colour: np.ndarray, depth_mm: np.ndarray, depth_range: tuple[float, float]):
    """(H', 2W', 3) uint8: ``colour`` beside the Turbo-coloured depth (millimetres),
    padded with black to even sides (the H.264 encoder's yuv420p needs them)."""
    depth = depth_colours(depth_mm.astype(np.float64) / 1000.0, *depth_range)
    panel = np.concatenate([colour, depth], axis=1)
    height, width = panel.shape[:2]
    return np.pad(panel, ((0, height % 2), (0, width % 2), (0, 0)))


def write_video(
    imageio_ffmpeg, folder: Path, names: list[str], depth_range: tuple[float, float], fps: float
) -> None:
    """Write ``folder``/video.mp4 (H.264) from the views ``names`` in colour/ and depth/."""
    first = video_panel(
        np.asarray(Image.open(folder / "colour" / names[0])),
        np.asarray(Image.open(folder / "depth" / names[0])),
        depth_range,
    )
    height, width = first.shape[:2]
    writer = imageio_ffmpeg.write_frames(
        str(folder / VIDEO_NAME), (width, height), fps=fps, macro_block_size=1
    )
    writer.send(None)  # start ffmpeg
    try:
        for name in names:
            panel = video_panel(
                np.asarray(Image.open(folder / "colour" / name).convert("RGB")),
                np.asarray(Image.open(folder / "depth" / name)),
                depth_range,
            )
            writer.send(np.ascontiguousarray(panel))
    finally:
        writer.close()
