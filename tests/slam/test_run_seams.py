"""The run loop's seams: frame sources of unknown length, observers, failures that keep
every completed frame (and resume exactly), and runs that leave no process-wide trace."""

from __future__ import annotations

import dataclasses
import json
import logging
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import DataConfig, load_config
from eslam.data import open_sequence
from eslam.data.source import IterableSource
from eslam.errors import ConfigError, RunInterrupted, RunStopped
from eslam.geometry.pose import se3_exp
from eslam.io.checkpoint import load_checkpoint
from eslam.io.trajectory import read_tum_trajectory
from eslam.slam.run.observers import FrameDone, MappingDone, RunEnd, RunObserverBase, RunStart
from eslam.slam.session import run_slam
from eslam.slam.tracking.base import TrackingQuality, TrackingResult
from eslam.slam.tracking.trackers import TRACKERS, make_tracker
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY, TINY_FRAMES, static_ate_cm, tiny_config

pytestmark = pytest.mark.slow  # integration: whole runs (still run in CI)


def _frames(sequence: Path):
    """A generator over the sequence's frames: no length, no indexing."""
    frames = open_sequence(DataConfig(path=str(sequence)))
    return frames.intrinsics, (frames[i] for i in range(len(frames)))


class Recorder(RunObserverBase):
    """Remembers every event; optionally raises at one of them."""

    def __init__(self, interrupt_at_mapping: int | None = None) -> None:
        self.events: list[str] = []
        self.interrupt_at_mapping = interrupt_at_mapping

    def on_start(self, start: RunStart) -> None:
        self.events.append(f"start {start.frames}")

    def on_frame(self, frame: FrameDone) -> None:
        self.events.append(f"frame {frame.index} {'M' if frame.mapped else '-'}")

    def on_mapping(self, mapping: MappingDone) -> None:
        self.events.append(f"map {mapping.index}")
        if mapping.index == self.interrupt_at_mapping:
            raise KeyboardInterrupt

    def on_finish(self, end: RunEnd) -> None:
        self.events.append(f"finish {end.complete} {end.frames}")

    def on_failure(self, error: BaseException, frames: int) -> None:
        self.events.append(f"failure {type(error).__name__} {frames}")


def test_a_generator_of_unknown_length_gives_the_disk_trajectory(
    tiny_sequence: Path, tiny_run, tmp_path: Path
) -> None:
    intrinsics, frames = _frames(tiny_sequence)
    recorder = Recorder()
    result = run_slam(
        tiny_config(tiny_sequence),
        tmp_path / "stream",
        source=IterableSource(intrinsics, frames, name="generator"),
        observers=[recorder],
    )
    np.testing.assert_allclose(result.poses, tiny_run.poses, rtol=0, atol=0)
    assert result.metrics["ate_rmse_cm"] == tiny_run.metrics["ate_rmse_cm"]
    assert (tmp_path / "stream" / "mesh.ply").is_file()
    # every 3rd frame is mapped as it arrives; the last one (11) when the stream ends
    assert recorder.events[0] == "start None"
    assert recorder.events[1:3] == ["map 0", "frame 0 M"]
    assert recorder.events[-3:] == ["frame 11 -", "map 11", f"finish True {TINY_FRAMES}"]
    assert (
        "run on generator: unknown number of frames"
        in (tmp_path / "stream" / "log.txt").read_text()
    )


def test_a_stream_without_depth_and_bound_is_refused(tiny_sequence: Path, tmp_path: Path) -> None:
    intrinsics, frames = _frames(tiny_sequence)
    blank = (f for f in frames for _ in range(3))  # 36 frames ...
    empty = (type(f)(f.index, f.rgb, np.zeros_like(f.depth), f.intrinsics) for f in blank)
    config = load_config(DEMO_CONFIG, [*TINY, "output.mesh=false"])  # no scene.bound
    # nothing was learnt from the 29 depthless frames: none is saved, a resume starts at 0
    with pytest.raises(RunStopped, match=r"first 30 frames has valid depth.*before its first"):
        run_slam(config, tmp_path / "r", source=IterableSource(intrinsics, empty))
    assert not (tmp_path / "r" / "map.pt").exists()


def test_a_corrupt_depth_image_stops_the_run_and_resume_finishes_it(
    tiny_sequence: Path, tiny_run, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    shutil.copytree(tiny_sequence, data)
    broken = data / "results" / "depth000006.png"
    good = broken.read_bytes()
    broken.write_bytes(b"not a png")
    out = tmp_path / "run"
    args = ["run", str(DEMO_CONFIG), "--data", str(data), "--out", str(out)]
    bound = load_config(tiny_run.run_dir / "config.yaml").scene.bound
    code = main([*args, f"scene.bound={bound}", *TINY])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "depth000006.png: unreadable depth image" in err
    assert f"stopped after 6 frames, saved in {out}" in err and f"eslam resume {out}" in err
    saved = load_checkpoint(out / "map.pt")
    assert len(saved["trajectory"]["timestamps"]) == 6  # frames 0..5
    _, poses = read_tum_trajectory(out / "trajectory.txt")
    assert len(poses) == 6
    assert "run stopped after 6 completed frames" in (out / "log.txt").read_text()

    broken.write_bytes(good)
    assert main(["resume", str(out)]) == 0
    resumed = load_checkpoint(out / "map.pt")["trajectory"]["poses"].double().numpy()
    np.testing.assert_allclose(resumed, tiny_run.poses, rtol=0, atol=1e-7)
    assert json.loads((out / "metrics.json").read_text())["frames"] == TINY_FRAMES


def test_an_interruption_during_mapping_is_rolled_back_and_resumes_exactly(
    tiny_sequence: Path, tiny_run, tmp_path: Path
) -> None:
    # frame 6 is mapped (every 3rd), then interrupted: the mapped field, the keyframe,
    # the pose and the generator draws of frame 6 are undone, frames 0..5 are saved
    recorder = Recorder(interrupt_at_mapping=6)
    out = tmp_path / "run"
    with pytest.raises(RunInterrupted, match=f"interrupted after 6 frames, saved in {out}"):
        run_slam(tiny_config(tiny_sequence), out, observers=[recorder])
    assert recorder.events[-2:] == ["map 6", "failure KeyboardInterrupt 6"]
    resumed = run_slam(load_config(out / "config.yaml"), out, resume=True)
    np.testing.assert_allclose(resumed.poses, tiny_run.poses, rtol=0, atol=1e-7)


def test_a_run_leaves_no_process_wide_state(tiny_sequence: Path, tmp_path: Path) -> None:
    threads = torch.get_num_threads()
    level = logging.getLogger("eslam").level
    handlers = list(logging.getLogger("eslam").handlers)
    rng = torch.get_rng_state()
    config = tiny_config(tiny_sequence, "threads=1", "output.mesh=false", "seed=1")
    run_slam(tiny_config(tiny_sequence, "output.mesh=false"), tmp_path / "a")
    second = run_slam(config, tmp_path / "b")
    assert torch.get_num_threads() == threads
    assert logging.getLogger("eslam").level == level
    assert logging.getLogger("eslam").handlers == handlers
    assert torch.equal(torch.get_rng_state(), rng)
    # the second run of this process equals the same run alone in a fresh process
    script = (
        "import sys, numpy as np\n"
        "from eslam.config import load_config\n"
        "from eslam.slam.session import run_slam\n"
        "r = run_slam(load_config(sys.argv[1]), sys.argv[2])\n"
        "np.save(sys.argv[3], r.poses)\n"
    )
    alone = tmp_path / "alone.npy"
    subprocess.run(
        [sys.executable, "-c", script, str(tmp_path / "b" / "config.yaml"), str(tmp_path / "c"),
         str(alone)],
        check=True,
        cwd=Path(__file__).resolve().parents[2],
    )  # fmt: skip
    # equal up to float32 rounding: on AVX-512 CPUs the math libraries' reductions can
    # round differently from one process to the next (seen with OMP_NUM_THREADS=1: 6e-8);
    # state carried over from the first run (random draws, settings) moves poses by far more
    np.testing.assert_allclose(second.poses, np.load(alone), rtol=0, atol=1e-6)
    assert second.metrics["peak_memory_mb"] > 0


class StandingStill:
    """A tracker that never moves the pose: what the loop tests must be able to catch."""

    def track(self, field, view, initial_pose, generator):
        return TrackingResult(pose=initial_pose, loss=torch.zeros(()))


def test_a_new_tracker_plugs_in_and_a_dead_one_is_caught(
    tiny_sequence: Path, tiny_run, tmp_path: Path, register
) -> None:
    register(TRACKERS, "still", lambda config: StandingStill())
    config = tiny_config(tiny_sequence, "output.mesh=false")
    config = dataclasses.replace(
        config,
        tracking=dataclasses.replace(config.tracking, method="still", constant_velocity=False),
        mapping=dataclasses.replace(config.mapping, optimise_poses=False),
    )
    assert isinstance(make_tracker(config), StandingStill)
    dead = run_slam(config, tmp_path / "dead")
    gt = read_tum_trajectory(tmp_path / "dead" / "trajectory_gt.txt")[1]
    assert len(gt) == TINY_FRAMES
    static = static_ate_cm(gt)
    # the dead tracker scores the static baseline the loop tests compare against ...
    assert dead.metrics["ate_rmse_cm"] == pytest.approx(static, rel=1e-3)
    # ... and the real one is far below it
    assert tiny_run.metrics["ate_rmse_cm"] < 0.3 * static
    unknown = dataclasses.replace(config, tracking=dataclasses.replace(config.tracking, method="x"))
    with pytest.raises(ConfigError, match=r"unknown tracking.method 'x'.*render"):
        make_tracker(unknown)


class FailsEveryOther:
    """Reports frames 3, 5, 7, ... as failed (with a pose far off), tracks the others
    by the rendering tracker."""

    def __init__(self, config) -> None:
        self.real = TRACKERS.make("render", config)
        self.calls = 0

    def track(self, field, view, initial_pose, generator):
        self.calls += 1
        result = self.real.track(field, view, initial_pose, generator)
        if self.calls % 2 == 0:
            return result
        far = initial_pose.clone()
        far[:3, 3] += 1.0
        return TrackingResult(far, result.loss, TrackingQuality(7, 0.1, 0.05, failed=True))


def test_a_failed_frame_keeps_the_prediction_and_is_no_keyframe(
    tiny_sequence: Path, tmp_path: Path, register
) -> None:
    register(TRACKERS, "flaky", FailsEveryOther)
    # recovery off: this is what a failed frame is when nothing recovers it
    config = tiny_config(
        tiny_sequence, "output.mesh=false", "mapping.every=1", "tracking.recovery.enabled=false"
    )
    config = dataclasses.replace(
        config, tracking=dataclasses.replace(config.tracking, method="flaky")
    )
    recorder = Recorder()
    result = run_slam(config, tmp_path / "run", observers=[recorder])
    failed = [e for e in recorder.events if e.startswith("frame") and e.endswith("-")]
    # mapping.every=1 maps every frame but the failed ones (frames 1, 3, 5, ...)
    assert failed == [f"frame {i} -" for i in range(1, TINY_FRAMES, 2)]
    assert result.metrics["tracking_failures"] == TINY_FRAMES // 2
    timings = json.loads((tmp_path / "run" / "timings.json").read_text())
    assert timings["tracking_failed"][:4] == [None, 1.0, None, 1.0]  # None: not judged
    assert timings["tracking_iterations"][1] == 7.0
    assert (
        "frame 1 (timestamp 1.000000): tracking failed (10% inliers"
        in (tmp_path / "run" / "log.txt").read_text()
    )
    # no failed frame kept the far pose: every estimate stays near the ground truth
    assert result.metrics["ate_rmse_cm"] < 5.0


class DegenerateStretch:
    """Tracks by the rendering tracker and reports frames 2-4 as seeing only 4 of the 6
    pose directions (the others: all 6). ``tracked`` counts calls across instances (a
    resumed run builds a new tracker): reset it before a run."""

    tracked = 0

    def __init__(self, config) -> None:
        self.real = TRACKERS.make("render", config)

    def track(self, field, view, initial_pose, generator):
        DegenerateStretch.tracked += 1  # call k tracks frame k
        result = self.real.track(field, view, initial_pose, generator)
        degenerate = 2 if 2 <= DegenerateStretch.tracked <= 4 else 0
        information = 0.001 if degenerate else 0.1
        quality = TrackingQuality(3, 0.95, 0.002, False, information, degenerate)
        return TrackingResult(result.pose, result.loss, quality)


@pytest.mark.parametrize("stop_after", [None, 4])
def test_degenerate_views_are_counted_and_logged_once_per_stretch(
    tiny_sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, register, stop_after
) -> None:
    register(TRACKERS, "degenerate", DegenerateStretch)
    monkeypatch.setattr(DegenerateStretch, "tracked", 0)
    config = tiny_config(tiny_sequence, "output.mesh=false")
    config = dataclasses.replace(
        config, tracking=dataclasses.replace(config.tracking, method="degenerate")
    )
    if stop_after is not None:  # stopped inside the stretch (frames 0-3 done), resumed
        run_slam(config, tmp_path / "run", stop_after=stop_after)
    result = run_slam(config, tmp_path / "run", resume=stop_after is not None)
    assert result.metrics["tracking_degenerate_frames"] == 3
    assert result.metrics["tracking_failures"] == 0
    timings = json.loads((tmp_path / "run" / "timings.json").read_text())
    assert timings["tracking_degenerate_directions"][:6] == [None, 0.0, 2.0, 2.0, 2.0, 0.0]
    assert timings["tracking_information"][2] == pytest.approx(0.001)
    log = (tmp_path / "run" / "log.txt").read_text()
    assert log.count("pins the pose down in only") == 1
    assert "frame 2: the view pins the pose down in only 4 of 6 directions" in log
    assert "frame 5: the view constrains the whole pose again (frames 2-4" in log


def test_a_run_without_the_degeneracy_test_claims_no_count(tiny_run) -> None:
    # the rendering tracker judges nothing: no count, not a count of 0
    assert "tracking_degenerate_frames" not in tiny_run.metrics


def test_a_map_saved_with_four_quality_columns_still_loads(
    tiny_sequence: Path, tiny_run, tmp_path: Path
) -> None:
    from eslam.io.checkpoint import save_checkpoint
    from eslam.slam.run.writer import run_metrics
    from eslam.slam.state import TRACKING_COLUMNS, load_state

    saved = load_checkpoint(tiny_run.run_dir / "map.pt", map_location="cpu")
    rows = [[5.0, 0.9, 0.001, float(i == 3)] for i in range(TINY_FRAMES)]
    old = tmp_path / "map.pt"
    save_checkpoint(old, {**saved, "tracking_quality": rows})  # before the information columns
    state = load_state(old, tiny_config(tiny_sequence), torch.device("cpu"))
    assert all(len(row) == len(TRACKING_COLUMNS) for row in state.tracking_quality)
    assert state.tracking_quality[3][:4] == [5.0, 0.9, 0.001, 1.0]
    assert np.isnan(state.tracking_quality[3][4:]).all()  # not computed then
    metrics = run_metrics(state, "cpu", 0.0)
    assert metrics["tracking_failures"] == 1
    assert "tracking_degenerate_frames" not in metrics


class KeepsThePrediction:
    """Moves the camera by a fixed small twist on the first frame it tracks, then finds
    every frame where the motion model predicted it (the SDF tracker's exp(xi) T with a
    zero step: the prediction itself, not rebuilt from a quaternion)."""

    STEP = torch.tensor([0.007, 0.001, 0.002, 0.003, 0.005, 0.001])

    def __init__(self, config) -> None:
        self.calls = 0

    def track(self, field, view, initial_pose, generator):
        self.calls += 1
        pose = (
            initial_pose if self.calls > 1 else se3_exp(self.STEP.to(initial_pose)) @ initial_pose
        )
        return TrackingResult(pose, torch.zeros(()), TrackingQuality(3, 0.9, 0.005, False))


def test_a_run_of_predicted_poses_stays_rigid(tmp_path: Path, register) -> None:
    """Each prediction extrapolates two poses that were predictions too: over 40 frames
    they must stay rigid and keep the first step's motion (the product R_k R_(k-1)^T R_k
    once multiplied float32's orthonormality error by ~2.4 a frame, and the `sdf`
    tracker lost the track to it after 26-35 frames)."""
    from eslam.synthetic import SynthConfig, write_synthetic_sequence

    frames = 44
    write_synthetic_sequence(tmp_path / "data", SynthConfig(frames=frames, width=40, height=30))
    register(TRACKERS, "predicted", KeepsThePrediction)
    # mapping must not refine the poses: they are made up, not what the images show
    config = tiny_config(tmp_path / "data", "output.mesh=false", "mapping.optimise_poses=false")
    config = dataclasses.replace(
        config, tracking=dataclasses.replace(config.tracking, method="predicted")
    )
    result = run_slam(config, tmp_path / "run")
    poses = result.poses  # as the loop held them, not as written
    assert np.isfinite(poses).all()
    gram = poses[:, :3, :3] @ poses[:, :3, :3].transpose(0, 2, 1)
    assert np.abs(gram - np.eye(3)).max() < 1e-5
    steps = np.linalg.inv(poses[1:-1]) @ poses[2:]
    np.testing.assert_allclose(steps, np.broadcast_to(steps[0], steps.shape), atol=1e-4)


def test_hybrid_lr_factor_scales_only_the_render_stage() -> None:
    config = load_config(
        None,
        [
            "tracking.method=hybrid",
            "tracking.hybrid.lr_factor=0.2",
            "tracking.render.lr_rotation=0.002",
        ],
    )
    stage = make_tracker(config).render.settings.tracking
    assert stage.iterations == config.tracking.hybrid.render_iterations
    assert stage.lr_translation == pytest.approx(0.2 * config.tracking.render.lr_translation)
    assert stage.lr_rotation == pytest.approx(0.0004)
    plain = make_tracker(
        dataclasses.replace(config, tracking=dataclasses.replace(config.tracking, method="render"))
    )
    assert plain.settings.tracking.lr_rotation == 0.002  # the render tracker keeps its own
    with pytest.raises(ConfigError, match="lr_factor"):
        load_config(None, ["tracking.hybrid.lr_factor=0"])
