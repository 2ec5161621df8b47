"""The ``eslam`` command: thin wrappers over the Python API.

Every command is a function users can call from Python too; this module only parses
arguments, calls it and turns user errors into one line on stderr with exit status 2.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import textwrap
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from eslam import __version__
from eslam.errors import ESLAMError, output_error

# Idle OpenMP threads sleep instead of spinning (set before anything imports torch): with
# other load on the machine, spinning threads slowed small CPU ops down ~20x here.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

EXIT_USER_ERROR = 2
"""Exit status of a run stopped by bad input, bad configuration or a bad argument."""

EXIT_INTERRUPTED = 130
"""Exit status of a command stopped by Ctrl-C or SIGTERM (128 + SIGINT, as shells do)."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block) naming the fix."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _image_size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` (e.g. 640x480) into (width, height)."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(part.isdigit() for part in parts):
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got '{text}'")
    width, height = int(parts[0]), int(parts[1])
    if width < 8 or height < 8:
        raise argparse.ArgumentTypeError(f"size must be at least 8x8, got '{text}'")
    return width, height


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got '{text}'") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got '{text}'")
    return value


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got '{text}'") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got '{text}'")
    return value


SETTINGS_WIDTH = 100
"""Line width of the settings list under ``eslam run --help``."""


def settings_epilog() -> str:
    """Every config key as ``section.key (default): docstring``, read off the dataclasses.

    The text under ``eslam run --help``: built from :func:`eslam.config.config_help`
    (the field docstrings of :class:`eslam.config.ESLAMConfig`), never written by hand.
    """
    from eslam.config import config_help

    def fill(text: str, indent: str = "", more: str = "") -> str:
        return textwrap.fill(
            " ".join(text.split()),
            SETTINGS_WIDTH,
            initial_indent=indent,
            subsequent_indent=more,
            break_long_words=False,
            break_on_hyphens=False,
        )

    lines = [
        fill(
            "settings (key=value after CONFIG): key (default): what it does. The defaults "
            "are the schema's; CONFIG and the files it inherits from (configs/base.yaml) "
            "change some of them."
        )
    ]
    for row in config_help():
        lines.append(fill(f"{row.key} ({row.default}): {row.doc}", "  ", "      "))
    return "\n".join(lines)


def _command_synth(args: argparse.Namespace) -> int:
    from eslam.synthetic import SynthConfig, write_synthetic_sequence

    width, height = args.size
    config = SynthConfig(
        frames=args.frames,
        width=width,
        height=height,
        seed=args.seed,
        scene=args.scene,
        depth_noise=args.depth_noise,
        missing_depth=args.missing_depth,
    )
    out_dir = write_synthetic_sequence(Path(args.out_dir), config, overwrite=args.overwrite)
    print(f"wrote {config.frames} frames ({width}x{height}, scene '{config.scene}') to {out_dir}")
    return 0


def _command_inspect(args: argparse.Namespace) -> int:
    from eslam.config import DataConfig
    from eslam.data import open_sequence
    from eslam.data.inspect import inspect_sequence

    sequence = open_sequence(
        DataConfig(format=args.format, path=args.path, depth_scale=args.depth_scale)
    )
    summary = inspect_sequence(sequence)
    print(summary.to_text())
    if summary.depth_problem is not None:
        raise summary.depth_problem  # the one line a run would stop with, exit status 2
    return 0


def _process_settings(config) -> None:
    """What a run asks of the process, set here (the process's owner), never by run_slam:
    torch's CPU threads (``threads=``)."""
    import torch

    if config.threads > 0:
        torch.set_num_threads(config.threads)


def _print_metrics(result) -> None:
    print(f"run folder: {result.run_dir}")
    for key, value in result.metrics.items():
        shown = f"{value:.4f}" if isinstance(value, float) else str(value)
        print(f"  {key:<20} {shown}")


def _command_run(args: argparse.Namespace) -> int:
    from eslam.config import load_config
    from eslam.io.run_dir import default_run_name
    from eslam.slam.session import run_slam

    overrides = list(args.overrides)
    if args.data is not None:
        overrides.append(f"data.path={args.data}")
    if args.device is not None:
        overrides.append(f"device={args.device}")
    for option in ("start", "stride", "max_frames"):
        if getattr(args, option) is not None:
            overrides.append(f"data.{option}={getattr(args, option)}")
    if args.realtime:
        overrides.append("data.realtime=true")
    config = load_config(args.config, overrides)
    out = Path(args.out) if args.out else Path(default_run_name(args.config))
    _process_settings(config)
    source = None
    if args.source is not None:
        from eslam.data.realsense import open_camera

        source = open_camera(args.source, args.camera_size, args.camera_fps, config.data)
    try:
        with _viewer(args, config, out) as observers:
            result = run_slam(
                config, out, overwrite=args.overwrite, source=source, observers=observers
            )
        _print_metrics(result)
    finally:
        if source is not None:
            source.close()
    return 0


def _viewer(args: argparse.Namespace, config, run_dir: Path):
    """The live viewer's observers (``--viewer``, ``--viewer-save``) as a context; without
    those options none, and nothing of the viewer is imported."""
    if args.viewer is None and args.viewer_save is None:
        return contextlib.nullcontext([])
    from eslam.workflows.live_viewer import viewer_observers

    return viewer_observers(config, run_dir, args.viewer, args.viewer_save)


def _add_viewer_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--viewer",
        choices=("rerun", "rerun-web"),
        help="show the run live: rerun = a rerun viewer here; rerun-web = served to a "
        "browser (ports 9090 and 9876); needs the [viewer] extra (docs/live.md)",
    )
    parser.add_argument(
        "--viewer-save", type=Path, metavar="FILE.rrd", help="record the viewer's stream to a file"
    )


def _command_configs(args: argparse.Namespace) -> int:
    from eslam.config.packaged import PACKAGED_CONFIGS, packaged_configs

    configs = packaged_configs()
    width = max(len(config.name) for config in configs)
    print(f"packaged configs (in {PACKAGED_CONFIGS}); pass a name as CONFIG to eslam run:")
    for config in configs:
        print(f"  {config.name:<{width}}  {config.summary}".rstrip())
    return 0


def _command_resume(args: argparse.Namespace) -> int:
    import dataclasses
    import os

    from eslam.config import load_config
    from eslam.errors import InputError
    from eslam.io.run_dir import RunDirectory
    from eslam.slam.session import run_slam

    run = RunDirectory(Path(args.run_dir))
    if not run.config.is_file():
        problem = "not found: not a run folder" if run.root.is_dir() else "run folder not found"
        raise InputError(
            run.config if run.root.is_dir() else run.root,
            problem,
            "pass the folder of a run started with `eslam run CONFIG --out RUN_DIR`",
        )
    config = load_config(run.config)
    if args.data is not None:  # the data moved: its fingerprint must still match
        data = dataclasses.replace(config.data, path=os.path.abspath(args.data))
        config = dataclasses.replace(config, data=data)
    _process_settings(config)
    with _viewer(args, config, run.root) as observers:
        _print_metrics(run_slam(config, run.root, resume=True, observers=observers))
    return 0


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got '{text}'") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got '{text}'")
    return value


def _command_mesh(args: argparse.Namespace) -> int:
    from eslam.slam.run.remesh import remesh_run

    result = remesh_run(args.run_dir, resolution=args.resolution, device=args.device)
    print(
        f"wrote {result.path} ({result.vertices} vertices, {result.faces} faces, "
        f"{result.resolution:g} m grid, {result.seconds:.1f} s)"
    )
    return 0


def _command_render(args: argparse.Namespace) -> int:
    from eslam.workflows.render_views import RenderOptions, render_run

    options = RenderOptions(
        trajectory=Path(args.trajectory) if args.trajectory else None,
        orbit=args.orbit,
        size=args.size,
        out=Path(args.out) if args.out else None,
        device=args.device,
        overwrite=args.overwrite,
        video=not args.no_video,
        fps=args.fps,
    )
    result = render_run(args.run_dir, options)
    width, height = result.size
    skipped = f", {result.skipped} missing poses skipped" if result.skipped else ""
    print(f"wrote {result.views} views ({width}x{height}{skipped}) to {result.out}")
    print(f"video: {result.video}" if result.video is not None else result.video_note)
    return 0


def _add_render_command(commands: argparse._SubParsersAction) -> None:
    from eslam.workflows.render_views import DEFAULT_ORBIT_VIEWS

    render = commands.add_parser(
        "render",
        help="render colour and depth views from a run's map.pt (no input depth)",
        description=(
            "Render views of the saved map along the run's estimated trajectory (default), "
            "a trajectory file or an orbit, with the run's camera: OUT/colour/NNNNNN.png "
            "(8-bit RGB), OUT/depth/NNNNNN.png (16-bit millimetres, 0 = nothing hit) and "
            "OUT/video.mp4 (needs imageio-ffmpeg, the [viewer] extra). See docs/render.md."
        ),
    )
    render.add_argument("run_dir", metavar="RUN_DIR", help="folder of a run (config.yaml, map.pt)")
    path = render.add_mutually_exclusive_group()
    path.add_argument(
        "--trajectory",
        metavar="FILE",
        help="poses to render: TUM file, Replica traj.txt or run folder (default: the run's)",
    )
    path.add_argument(
        "--orbit",
        nargs="?",
        const=DEFAULT_ORBIT_VIEWS,
        type=_positive_int,
        metavar="N",
        help=f"N views on a circle around the scene's centre (default {DEFAULT_ORBIT_VIEWS})",
    )
    render.add_argument(
        "--size", type=_image_size, metavar="WxH", help="image size (default: the run's)"
    )
    render.add_argument("--out", metavar="DIR", help="output folder (default RUN_DIR/render)")
    render.add_argument(
        "--device", default="cpu", help="auto, cpu, cuda, cuda:N or mps (default cpu)"
    )
    render.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    render.add_argument(
        "--fps", type=_positive_float, default=30.0, help="video frame rate (default 30)"
    )
    render.add_argument("--no-video", action="store_true", help="images only, no video.mp4")
    render.set_defaults(handler=_command_render)


def _command_demo(args: argparse.Namespace) -> int:
    from eslam.evaluate.report import metrics_text
    from eslam.workflows.demo import demo_config, run_demo

    config = demo_config(Path(args.out), tuple(args.overrides))
    _process_settings(config)
    result = run_demo(Path(args.out), config)
    print(f"run folder: {result.run_dir} (report.md holds the table and plots)")
    print(metrics_text(result.metrics))
    return 0


def _command_eval(args: argparse.Namespace) -> int:
    from eslam.evaluate.report import metrics_text
    from eslam.workflows.evaluate_run import EvaluationOptions, evaluate_run

    options = EvaluationOptions(
        gt_mesh=Path(args.gt_mesh).absolute() if args.gt_mesh else None,
        protocol=args.protocol,
        samples=args.samples,
        exact=args.exact,
        depth_l1_views=args.views,
        seed=args.seed,
        cull_every=args.cull_every,
        max_unobserved_fraction=args.max_unobserved,
        device=args.device,
        data=Path(args.data).absolute() if args.data else None,
        progress=True,
    )
    metrics = evaluate_run(args.run_dir, options)
    print(f"wrote {Path(args.run_dir) / 'metrics.json'} and report.md")
    print(metrics_text(metrics))
    return 0


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got '{text}'")
    return value


def _command_ate(args: argparse.Namespace) -> int:
    from eslam.errors import InputError
    from eslam.evaluate.report import titled_table
    from eslam.evaluate.trajectory import TimedPoses, trajectory_ate, trajectory_rpe
    from eslam.io.run_dir import json_text
    from eslam.io.trajectory import read_trajectory

    gt = TimedPoses(*read_trajectory(args.gt, ground_truth=True, allow_missing=True))
    est = TimedPoses(*read_trajectory(args.est, allow_missing=True))
    try:
        result = trajectory_ate(gt, est, args.align == "sim3", args.max_diff)
    except ValueError as error:
        raise InputError(
            args.est, str(error), "check that both files cover the same frames, or --max-diff"
        ) from None
    metrics = {**result.as_dict(), "align": args.align, "max_diff_s": args.max_diff}
    try:  # relative motions need no alignment; a pair needs two consecutive matched poses
        metrics.update(trajectory_rpe(gt, est, 1, args.max_diff).as_dict())
    except ValueError:
        pass  # no consecutive finite pair: the ATE stands alone
    if args.json:
        print(json_text({**metrics, "gt": args.gt, "est": args.est}))
    else:
        print(titled_table(f"ATE of {args.est} against {args.gt}", metrics))
    return 0


def _command_recon(args: argparse.Namespace) -> int:
    from eslam.errors import ConfigError, InputError
    from eslam.evaluate.depth_l1 import DepthL1Options, depth_l1
    from eslam.evaluate.reconstruction import ReconstructionOptions, evaluate_reconstruction
    from eslam.evaluate.report import titled_table
    from eslam.io.mesh_files import find_mesh, read_mesh
    from eslam.io.run_dir import json_text

    rec_path, gt_path = find_mesh(args.rec), find_mesh(args.gt)
    reconstruction, ground_truth = read_mesh(rec_path), read_mesh(gt_path)
    options = ReconstructionOptions(samples=args.samples, seed=args.seed, exact=args.exact)
    try:
        metrics: dict[str, object] = evaluate_reconstruction(
            reconstruction, ground_truth, options
        ).as_dict()
    except ValueError as error:
        raise InputError(rec_path, str(error), "check both meshes have triangles") from None
    if args.depth_l1:
        uncut = read_mesh(args.gt_uncut) if args.gt_uncut else None
        depth_options = DepthL1Options(views=args.views, seed=args.seed)
        try:
            metrics.update(depth_l1(reconstruction, ground_truth, depth_options, uncut).as_dict())
        except ImportError as error:
            raise ConfigError(f"--depth-l1: {error}") from None
    if args.json:
        print(json_text({**metrics, "rec": rec_path, "gt": gt_path}))
    else:
        print(titled_table(f"reconstruction {rec_path} against {gt_path}", metrics))
    return 0


def _command_sweep(args: argparse.Namespace) -> int:
    from eslam.workflows.sweep import check_inputs, describe_cells, plan_cells, run_sweep
    from eslam.workflows.sweep_file import load_sweep

    names = [[n for n in (text or "").split(",") if n] for text in (args.datasets, args.variants)]
    sweep = load_sweep(args.sweep).select(*names)
    if args.dry_run:
        cells = plan_cells(sweep, args.out, args.overrides)
        check_inputs(cells)
        print(describe_cells(cells))
        return 0
    summary = run_sweep(
        sweep, args.out, args.backend, args.jobs, args.address, extra=args.overrides
    )
    print(summary.text())
    if summary.count("done") + summary.count("skipped"):
        print(f"tables: eslam table {args.out}")
    return 1 if summary.failed else 0


def _command_table(args: argparse.Namespace) -> int:
    from eslam.workflows.table import write_table

    result = write_table(args.dir, plots=not args.no_plots)
    print(f"wrote {', '.join(str(path) for path in result.files[:3])} ({len(result.rows)} rows)")
    if result.unfinished:
        print(f"left out {len(result.unfinished)} unfinished cells (listed in table.md)")
    return 0


def _add_sweep_commands(commands: argparse._SubParsersAction) -> None:
    sweep = commands.add_parser(
        "sweep",
        help="run a grid of runs (datasets x variants x seeds) from a sweep file, resumable",
        description=(
            "Run and evaluate every cell of SWEEP (a YAML sweep file, docs/sweeps.md) into "
            "OUT/<dataset>/<variant>/seed<k>/; finished cells of the same config are "
            "skipped, failed ones recorded in their cell.json. Exit status 1 when a cell "
            "failed. Then `eslam table OUT`."
        ),
    )
    sweep.add_argument("sweep", metavar="SWEEP", help="sweep file (YAML)")
    sweep.add_argument("overrides", nargs="*", metavar="key=value", help="every cell, last")
    sweep.add_argument("--out", required=True, help="output folder (shared by all Ray nodes)")
    sweep.add_argument("--backend", choices=("local", "ray"), default="local", help="(local)")
    sweep.add_argument(
        "--jobs", type=_positive_int, default=1, help="local: cells at a time, in processes (1)"
    )
    sweep.add_argument(
        "--address", help="ray: cluster to join (auto, HOST:6379); default a new one"
    )
    sweep.add_argument("--datasets", metavar="A,B", help="run only these datasets of SWEEP")
    sweep.add_argument("--variants", metavar="A,B", help="run only these variants of SWEEP")
    sweep.add_argument(
        "--dry-run", action="store_true", help="check the input, print the cells, run nothing"
    )
    sweep.set_defaults(handler=_command_sweep)

    table = commands.add_parser(
        "table",
        help="mean +- std over seeds of a sweep's cells, beside the paper's numbers",
        description=(
            "Aggregate the finished cells under DIR (eslam sweep --out DIR) into "
            "DIR/table.md, table.csv, table.json and DIR/plots/<metric>.png."
        ),
    )
    table.add_argument("dir", metavar="DIR", help="the output folder of eslam sweep")
    table.add_argument("--no-plots", action="store_true", help="tables only (no matplotlib)")
    table.set_defaults(handler=_command_table)


def _add_evaluation_commands(commands: argparse._SubParsersAction) -> None:
    from eslam.evaluate.depth_l1 import RELEASE_VIEWS
    from eslam.evaluate.reconstruction import RELEASE_SAMPLES

    ate = commands.add_parser(
        "ate",
        help="absolute trajectory error (and relative pose error) between two trajectories",
        description=(
            "ATE after Umeyama alignment of the estimate onto the ground truth: RMSE, mean, "
            "median, max (cm). GT and EST are TUM files (timestamp tx ty tz qx qy qz qw), "
            "Replica traj.txt files (16 numbers per line; timestamps = line numbers) or run "
            "folders (GT reads trajectory_gt.txt, EST trajectory.txt). Poses are matched by "
            "timestamp; pairs with a missing (nan/inf) pose are left out and counted."
        ),
    )
    ate.add_argument("gt", metavar="GT", help="ground-truth trajectory file or run folder")
    ate.add_argument("est", metavar="EST", help="estimated trajectory file or run folder")
    ate.add_argument(
        "--align",
        choices=("se3", "sim3"),
        default="se3",
        help="rigid (se3, the paper's) or similarity (sim3) alignment",
    )
    ate.add_argument(
        "--max-diff",
        type=_non_negative_float,
        default=0.01,
        metavar="S",
        help="largest timestamp difference of a matched pair, seconds (default 0.01)",
    )
    ate.add_argument("--json", action="store_true", help="print JSON instead of a table")
    ate.set_defaults(handler=_command_ate)

    recon = commands.add_parser(
        "recon",
        help="accuracy / completion / ratio / F1 (and depth L1) of a mesh against a GT mesh",
        description=(
            "Sample both meshes (area-weighted, seeded) and measure accuracy (rec to GT), "
            "completion (GT to rec), completion ratio (< 5 cm), precision / recall / F1 "
            "(< 1 cm). REC and GT are mesh files or run folders (mesh_culled.ply, else "
            "mesh.ply). --exact measures distances to the other mesh's triangles instead of "
            "its samples; --depth-l1 adds the depth L1 over random virtual views."
        ),
    )
    recon.add_argument("rec", metavar="REC", help="reconstructed mesh or run folder")
    recon.add_argument("gt", metavar="GT", help="ground-truth mesh or run folder")
    recon.add_argument("--exact", action="store_true", help="distances to the other surface")
    recon.add_argument(
        "--samples",
        type=_positive_int,
        default=RELEASE_SAMPLES,
        metavar="N",
        help=f"points sampled per mesh (default {RELEASE_SAMPLES}, the ESLAM protocol)",
    )
    recon.add_argument("--seed", type=int, default=0, help="seed of samples and views")
    recon.add_argument("--depth-l1", action="store_true", help="also the depth L1 (slower)")
    recon.add_argument(
        "--views",
        type=_positive_int,
        default=RELEASE_VIEWS,
        metavar="N",
        help=f"virtual views of the depth L1 (default {RELEASE_VIEWS})",
    )
    recon.add_argument(
        "--gt-uncut",
        metavar="PATH",
        help="the GT mesh before culling: depth L1 views that see culled-away space are redrawn",
    )
    recon.add_argument("--json", action="store_true", help="print JSON instead of a table")
    recon.set_defaults(handler=_command_recon)


def build_parser() -> argparse.ArgumentParser:
    """The ``eslam`` argument parser with every sub-command."""
    parser = _Parser(
        prog="eslam",
        description="ESLAM: dense neural RGB-D SLAM with multi-scale feature planes.",
    )
    parser.add_argument("--version", action="version", version=f"eslam {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    commands.required = True

    from eslam.synthetic import SCENES, SynthConfig

    defaults = SynthConfig()
    synth = commands.add_parser(
        "synth",
        help="write a synthetic RGB-D sequence with exact ground truth (Replica layout)",
        description=(
            "Render a procedural room by exact ray casting and write it in the Replica "
            "layout: results/frame*.jpg, results/depth*.png, traj.txt, cam_params.json, "
            "plus the ground-truth mesh.ply and synth.json."
        ),
    )
    synth.add_argument("out_dir", metavar="OUT_DIR", help="folder to create")
    synth.add_argument(
        "--frames", type=_positive_int, default=defaults.frames, help="frames to render"
    )
    synth.add_argument(
        "--size",
        type=_image_size,
        default=(defaults.width, defaults.height),
        metavar="WxH",
        help=f"image size (default {defaults.width}x{defaults.height})",
    )
    synth.add_argument("--seed", type=int, default=defaults.seed, help="scene and trajectory seed")
    synth.add_argument(
        "--scene", choices=sorted(SCENES), default=defaults.scene, help="scene builder"
    )
    synth.add_argument("--depth-noise", action="store_true", help="add sensor-like depth noise")
    synth.add_argument(
        "--missing-depth", action="store_true", help="drop depth like a sensor does (0 = invalid)"
    )
    synth.add_argument("--overwrite", action="store_true", help="replace OUT_DIR if it exists")
    synth.set_defaults(handler=_command_synth)

    from eslam.data import DATASETS

    inspect = commands.add_parser(
        "inspect",
        help="read and check every frame of a sequence, print a summary",
        description=(
            "Read every frame of a sequence with its reader, check it (images, depth, "
            "poses) and print frame count, camera, depth range and trajectory length."
        ),
    )
    inspect.add_argument("path", metavar="PATH", help="sequence folder")
    inspect.add_argument(
        "--format", choices=sorted(DATASETS), default="replica", help="dataset layout"
    )
    inspect.add_argument(
        "--depth-scale",
        type=_positive_float,
        metavar="UNITS",
        help="depth units per metre (sets data.depth_scale; default: the layout's own)",
    )
    inspect.set_defaults(handler=_command_inspect)

    run = commands.add_parser(
        "run",
        help="run ESLAM on a sequence and write a run folder",
        description=textwrap.fill(
            "Track every frame and map every k-th; write config.yaml, trajectory.txt "
            "(TUM), trajectory_gt.txt, map.pt, mesh.ply, metrics.json and timings.json. "
            "Settings are `key.sub=value` overrides of CONFIG (listed below).",
            SETTINGS_WIDTH,
        ),
        epilog=settings_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument(
        "config",
        metavar="CONFIG",
        help="YAML config file, or a packaged config's name from any directory "
        "(e.g. replica/room0; `eslam configs` lists them)",
    )
    run.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    run.add_argument("--data", help="sequence folder (sets data.path)")
    run.add_argument("--out", help="run folder (default runs/NAME-TIME)")
    run.add_argument("--device", help="auto, cpu, cuda, cuda:N or mps (sets device)")
    run.add_argument("--start", type=int, help="first frame to use (sets data.start)")
    run.add_argument("--stride", type=int, help="use every N-th frame (sets data.stride)")
    run.add_argument("--max-frames", type=int, help="use at most N frames (sets data.max_frames)")
    run.add_argument("--overwrite", action="store_true", help="reuse an existing run folder")
    run.add_argument(
        "--realtime",
        action="store_true",
        help="drop frames that arrive while busy, keep the newest; replay a recording at its "
        "recorded rate (sets data.realtime; always on for a live camera; docs/live.md)",
    )
    run.add_argument(
        "--source",
        metavar="realsense[:SERIAL]",
        help="a live RealSense camera instead of --data (docs/live.md; the realsense extra)",
    )
    run.add_argument(
        "--camera-size", type=_image_size, default=(640, 480), metavar="WxH",
        help="live camera: depth and colour size (default 640x480)",
    )  # fmt: skip
    run.add_argument(
        "--camera-fps", type=_positive_int, default=30, help="live camera: frame rate (30)"
    )
    _add_viewer_options(run)
    run.set_defaults(handler=_command_run)

    configs = commands.add_parser(
        "configs",
        help="list the packaged configs (names eslam run takes from any directory)",
        description=(
            "List the configs shipped with eslam (eslam/configs/), by the name `eslam run` "
            "takes as CONFIG from any directory, e.g. `eslam run replica/room0 --data PATH`; "
            "a path that exists is used as it is."
        ),
    )
    configs.set_defaults(handler=_command_configs)

    resume = commands.add_parser(
        "resume",
        help="continue an interrupted run from its last checkpoint",
        description=(
            "Continue the run in RUN_DIR from its last checkpoint (map.pt), or from frame 0 "
            "when it stopped before saving one. The sequence must be the one the run "
            "started on (frame count, first and last files, camera: input.json); "
            "--data points to it where it moved. See docs/reliability.md."
        ),
    )
    resume.add_argument("run_dir", metavar="RUN_DIR", help="folder of the interrupted run")
    resume.add_argument(
        "--data", metavar="PATH", help="the run's sequence, where it moved (sets data.path)"
    )
    _add_viewer_options(resume)
    resume.set_defaults(handler=_command_resume)

    mesh = commands.add_parser(
        "mesh",
        help="extract RUN_DIR/mesh.ply again from the run's map.pt",
        description=(
            "Marching cubes of the saved field over the space the keyframes observed; "
            "replaces RUN_DIR/mesh.ply (atomically)."
        ),
    )
    mesh.add_argument("run_dir", metavar="RUN_DIR", help="folder of a run (config.yaml, map.pt)")
    mesh.add_argument(
        "--resolution",
        type=_positive_float,
        metavar="M",
        help="grid step in metres (default: the run's output.mesh_resolution)",
    )
    mesh.add_argument(
        "--device", default="cpu", help="auto, cpu, cuda, cuda:N or mps (default cpu)"
    )
    mesh.set_defaults(handler=_command_mesh)
    _add_render_command(commands)

    demo = commands.add_parser(
        "demo",
        help="synthetic scene, end to end: generate, run, evaluate (a few minutes on CPU)",
        description=(
            "Write a 60-frame synthetic room to OUT/data, run ESLAM with the CPU preset "
            "(configs/demo.yaml) to OUT/run and print the metrics."
        ),
    )
    demo.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    demo.add_argument("overrides", nargs="*", metavar="key=value", help="config overrides")
    demo.set_defaults(handler=_command_demo)

    evaluation = commands.add_parser(
        "eval",
        help="score a finished run: ATE, mesh metrics against a GT mesh, report.md",
        description=(
            "ATE (all statistics) of RUN_DIR; with --gt-mesh also culling of both meshes "
            "(--protocol), accuracy, completion, completion ratio, precision/recall/F1 "
            "and depth L1. Adds to metrics.json, writes mesh_culled.ply, report.md and "
            "two plots (needs the [eval] and [viz] extras)."
        ),
    )
    evaluation.add_argument("run_dir", metavar="RUN_DIR", help="a finished run folder")
    evaluation.add_argument("--gt-mesh", help="ground-truth mesh in the poses' world frame")
    evaluation.add_argument(
        "--data", metavar="PATH", help="the run's sequence, where it moved (default: config.yaml's)"
    )
    evaluation.add_argument(
        "--protocol", choices=("eslam", "nice"), default="eslam", help="culling (default eslam)"
    )
    evaluation.add_argument(
        "--samples", type=_positive_int, default=450_000, help="samples per mesh (default 450000)"
    )
    evaluation.add_argument("--exact", action="store_true", help="point-to-surface distances")
    evaluation.add_argument(
        "--views",
        type=_non_negative_int,
        default=1000,
        help="depth-L1 virtual views; 0 = skip (1000)",
    )
    evaluation.add_argument("--seed", type=int, default=0, help="samples and views (0)")
    evaluation.add_argument(
        "--cull-every", type=_positive_int, default=1, help="cull with every k-th frame (1)"
    )
    evaluation.add_argument(
        "--max-unobserved",
        type=float,
        default=0.0,
        help="share of a view's pixels that may see unobserved space (0, the release)",
    )
    evaluation.add_argument(
        "--device", default="cpu", help="device for culling: auto, cpu, cuda, cuda:N or mps (cpu)"
    )
    evaluation.set_defaults(handler=_command_eval)
    _add_evaluation_commands(commands)
    _add_sweep_commands(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``eslam`` console script; returns the exit status."""
    parser = build_parser()
    # key=value overrides may follow options (`run CONFIG --data X key=value`), which
    # argparse cannot match to a positional list once it has been consumed: collect them.
    args, extra = parser.parse_known_args(argv)
    if extra:
        overridable = hasattr(args, "overrides")
        bad = [item for item in extra if not overridable or item.startswith("-") or "=" not in item]
        given = list(sys.argv[1:] if argv is None else argv)
        options = [item for item in extra if item.startswith("--")]
        hint = _setting_hint(options, given) if overridable else None
        if hint is not None:
            print(
                f"eslam {args.command}: error: {hint} (see eslam {args.command} --help)",
                file=sys.stderr,
            )
            return EXIT_USER_ERROR
        if bad:
            parser.error(f"unrecognized arguments: {' '.join(bad)}")
        args.overrides = [*args.overrides, *extra]
    previous = _terminate_as_interrupt()
    try:
        return int(args.handler(args))
    except ESLAMError as error:
        print(f"eslam {args.command}: error: {error}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as error:
        # A write outside eslam.atomic (a folder created, log.txt opened): the same one
        # line as an atomic write's OutputError when the user can fix it, else a bug.
        mapped = output_error(error, error.filename) if error.filename else None
        if mapped is None:
            raise
        print(f"eslam {args.command}: error: {mapped}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt as interrupt:
        detail = str(interrupt) or "interrupted"
        if not detail.startswith("interrupted"):
            detail = f"interrupted: {detail}"
        print(f"eslam {args.command}: {detail}", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _setting_hint(unknown: Sequence[str], argv: Sequence[str]) -> str | None:
    """For an unknown option ``--name [VALUE]`` of ``argv`` that names a setting
    (``--format tum``), the message saying to pass it as ``key=VALUE`` after the config;
    None when none does."""
    from eslam.config import config_help

    for item in unknown:
        option, equals, value = item.partition("=")
        if not equals:
            position = list(argv).index(item)
            after = argv[position + 1] if position + 1 < len(argv) else ""
            value = after if after and not after.startswith("-") and "=" not in after else "VALUE"
        name = option[2:].replace("-", "_")
        keys = [row.key for row in config_help() if row.key.rsplit(".", 1)[-1] == name]
        if keys:
            settings = " or ".join(f"{key}={value}" for key in keys)
            return (
                f"{option} is no option here: settings follow the config as key=value, "
                f"e.g. {settings}"
            )
    return None


def _raise_interrupt(signum: int, frame: object) -> NoReturn:
    raise KeyboardInterrupt


def _terminate_as_interrupt():
    """Make SIGTERM stop a command like Ctrl-C (runs save their frames); return the old
    handler, or None where signals cannot be set (not the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_interrupt)


if __name__ == "__main__":
    sys.exit(main())
