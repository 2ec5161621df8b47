"""Runs through the feeds: read-ahead and cached views change nothing, real-time runs drop
frames consistently and end cleanly on Ctrl-C, speed figures in metrics.json."""

from __future__ import annotations

import itertools
import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.data import open_sequence
from eslam.data.source import IterableSource
from eslam.errors import ConfigError, InputError
from eslam.io.trajectory import read_tum_trajectory
from eslam.render.rays import camera_directions
from eslam.slam.mapping.keyframe_views import KeyframeViews, view_bytes
from eslam.slam.mapping.keyframes import KeyframeStore
from eslam.slam.run.observers import FrameDone, MappingStep, RunObserverBase
from eslam.slam.run.progress import ProgressObserver
from eslam.slam.run.stops import stopped_error
from eslam.slam.run.writer import WallTime, speed_metrics
from eslam.slam.session import run_slam
from eslam.slam.trajectory import Trajectory
from eslam.slam.views import make_view
from eslam.workflows.evaluate_run import sequence_frames
from tests.conftest import tiny_config

QUICK = (
    "mapping.first_iterations=5",
    "mapping.iterations=3",
    "tracking.render.iterations=3",
    "output.checkpoint_every=100",
)
"""Fewer iterations than the tiny settings: these tests compare runs, not accuracy."""

FEW_RAYS = (
    "mapping.rays=120",
    "tracking.render.rays=60",
    "render.samples_stratified=6",
    "render.samples_surface=3",
)


def test_prefetch_and_cached_views_leave_the_trajectory_bit_identical(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    common = (*QUICK, *FEW_RAYS, "data.max_frames=4", "mapping.every=1", "output.mesh=false")
    plain = tiny_config(tiny_sequence, *common, "data.prefetch=0", "mapping.view_cache_mb=0")
    # a cache of two 80x60 views (0.115 MB each): views are dropped and built again
    fast = tiny_config(tiny_sequence, *common, "data.prefetch=2", "mapping.view_cache_mb=0.3")
    before = run_slam(plain, tmp_path / "plain")
    after = run_slam(fast, tmp_path / "fast")
    assert before.poses.shape == (4, 4, 4)
    np.testing.assert_array_equal(after.poses, before.poses)
    assert after.metrics["ate_rmse_cm"] == before.metrics["ate_rmse_cm"]
    for name in ("fps_wall", "fps_wall_after_first", "fps_tracking", "first_frame_s"):
        assert after.metrics[name] > 0
    assert after.metrics["wall_frames"] == 4


def test_keyframe_views_equal_fresh_ones_within_the_budget(tiny_sequence: Path) -> None:
    sequence = open_sequence(tiny_config(tiny_sequence).data)
    trajectory = Trajectory()
    store = KeyframeStore(sequence.intrinsics, trajectory)
    for i in range(4):
        trajectory.append(torch.eye(4), float(i), None)
        store.add(sequence[i], i)
    directions = camera_directions(sequence.intrinsics, "cpu")
    size = view_bytes(make_view(store.rgb(0), store.depth(0), directions))
    views = KeyframeViews(store, directions, torch.device("cpu"), budget_mb=2.5 * size / 1e6)
    for k in (0, 1, 2, 3, 1):
        view, fresh = views.view(k), make_view(store.rgb(k), store.depth(k), directions)
        for name in ("rgb", "depth", "cumulative", "count"):
            assert torch.equal(getattr(view, name), getattr(fresh, name))
    assert len(views) == 2  # the budget holds two (3 and 1): the least recently used left
    kept = views.view(1)
    assert views.view(1) is kept  # kept, not rebuilt
    first = views.view(0)  # 3 leaves
    views.forget_from(1)  # keyframes from 1 on were rolled back
    assert len(views) == 1 and views.view(0) is first
    assert views.view(1) is not kept


def test_a_hidden_progress_bar_reads_nothing_from_the_run() -> None:
    class Untouchable:
        def __getattr__(self, name: str):
            raise AssertionError(f"the hidden bar read state.{name}")

    class Start:
        state = Untouchable()
        frames = 12

    progress = ProgressObserver(False)
    progress.on_start(Start())  # type: ignore[arg-type]
    done = FrameDone(9, torch.eye(4), True, None, False, 0.1, 0.0)  # an ATE frame
    progress.on_frame(done)
    assert progress.bar is None


def test_speed_metrics_follow_their_definitions() -> None:
    wall = WallTime(frames=11, wall_s=12.0, first_frame_s=2.0, poses_s=8.0)
    metrics = speed_metrics(wall, [0.5] * 11)
    assert metrics["fps_wall"] == pytest.approx(11 / 12.0)
    assert metrics["fps_wall_after_first"] == pytest.approx(10 / 10.0)
    assert metrics["fps_poses_after_first"] == pytest.approx(10 / 8.0)  # final call left out
    assert metrics["fps_tracking"] == pytest.approx(11 / 5.5)  # Co-SLAM: frames / tracking s
    alone = speed_metrics(WallTime(1, 2.0, 2.0), [0.0])
    assert "fps_wall_after_first" not in alone and "fps_poses_after_first" not in alone


def test_a_real_time_replay_drops_frames_in_order_and_pairs_the_right_ground_truth(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    config = tiny_config(tiny_sequence, *QUICK, "data.realtime=true")
    with pytest.raises(ConfigError, match=r"frame numbers.*replay_fps"):
        run_slam(config, tmp_path / "no-rate")  # Replica layout: no timestamps
    assert not (tmp_path / "no-rate").exists()
    # a 1000 fps replay: the first frame's mapping call alone outlasts the stream
    config = tiny_config(tiny_sequence, *QUICK, "data.realtime=true", "data.replay_fps=1000")
    result = run_slam(config, tmp_path / "rt")
    metrics = json.loads((tmp_path / "rt" / "metrics.json").read_text())
    timings = json.loads((tmp_path / "rt" / "timings.json").read_text())
    processed = timings["source_index"]
    assert metrics == result.metrics
    assert metrics["frames_received"] == 12
    assert metrics["frames"] == len(processed) == len(result.poses)
    assert metrics["frames_dropped"] == 12 - len(processed) > 0
    assert processed[-1] == 11  # the newest is kept: the stream's last frame is processed
    assert all(a < b for a, b in itertools.pairwise(processed))  # never reordered
    # each processed frame keeps its own timestamp and ground truth
    sequence = open_sequence(config.data)
    times, _ = read_tum_trajectory(tmp_path / "rt" / "trajectory.txt")
    np.testing.assert_array_equal(times, sequence.timestamps()[processed])
    _, gt = read_tum_trajectory(tmp_path / "rt" / "trajectory_gt.txt")
    np.testing.assert_allclose(gt, sequence.gt_poses()[processed], atol=1e-6)
    rows, frames = sequence_frames(times, sequence)  # what `eslam eval` culls the meshes with
    assert rows.tolist() == list(range(len(processed))) and frames.tolist() == processed
    assert "dropped" in (tmp_path / "rt" / "log.txt").read_text()
    with pytest.raises(ConfigError, match=r"real time.*cannot be resumed"):
        run_slam(config, tmp_path / "rt", resume=True)
    # a real-time run stopped by an error says so instead of naming `eslam resume`
    stopped = stopped_error(InputError(Path("x.png"), "unreadable", "fix it"), 2, tmp_path, False)
    assert "start a new run" in str(stopped) and "eslam resume" not in str(stopped)


class CtrlC(RunObserverBase):
    """Presses Ctrl-C in the middle of mapping frame ``index`` (a keyframe)."""

    def __init__(self, index: int) -> None:
        self.index = index

    def on_mapping_step(self, step: MappingStep) -> None:
        if step.index == self.index and step.done == 1:
            raise KeyboardInterrupt


def test_ctrl_c_ends_a_live_run_cleanly(tiny_sequence: Path, tmp_path: Path) -> None:
    # mapping in turn: Ctrl-C lands inside a mapping call (test_concurrent_mapping.py
    # presses it in a run that maps beside the tracker)
    config = tiny_config(tiny_sequence, *QUICK, "mapping.concurrent=false")
    sequence = open_sequence(config.data)
    closed = threading.Event()

    def camera():  # a live camera at ~100 fps, endless
        try:
            i = 0
            while True:
                yield sequence[i % len(sequence)]
                i += 1
                time.sleep(0.01)
        finally:
            closed.set()

    camera_source = IterableSource(sequence.intrinsics, camera(), name="camera", live=True)
    # frame 3 (a keyframe: mapping.every=3) is rolled back; frames 0-2 make the run
    result = run_slam(config, tmp_path / "live", source=camera_source, observers=[CtrlC(3)])
    run = tmp_path / "live"
    for name in ("map.pt", "trajectory.txt", "mesh.ply", "metrics.json", "timings.json"):
        assert (run / name).is_file(), name
    metrics = result.metrics
    assert metrics["frames"] == 3 and len(result.poses) == 3
    assert metrics["frames_received"] == 3 + metrics["frames_dropped"]
    assert "ended by Ctrl-C" in (run / "log.txt").read_text()
    assert closed.is_set()  # the camera was released
    assert not any(t.name == "eslam-realtime" for t in threading.enumerate())
