"""The viewer observer: what it shows and when, and that it leaves the run as it was."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.config import DataConfig, ViewerConfig, load_config
from eslam.data import open_sequence
from eslam.slam.run.observers import FrameDone, MappingDone, RunEnd, RunStart
from eslam.slam.run.viewer import ViewerObserver
from eslam.slam.state import load_state


class RecordingSink:
    """A ViewerSink that keeps what it is shown."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def show_camera(self, index, intrinsics, pose, rgb, depth) -> None:
        shapes = [None if image is None else image.shape for image in (rgb, depth)]
        self.calls.append(("camera", index, pose.copy(), *shapes))

    def show_trajectory(self, index, estimated, ground_truth) -> None:
        self.calls.append(("trajectory", index, estimated.copy(), ground_truth.copy()))

    def show_loops(self, index, segments) -> None:
        self.calls.append(("loops", index, segments.copy()))

    def show_rendered(self, index, intrinsics, depth, rgb) -> None:
        self.calls.append(("rendered", index, intrinsics.size, depth.copy(), rgb.shape))

    def show_mesh(self, index, mesh) -> None:
        self.calls.append(("mesh", index, len(mesh.faces)))

    def show_scalars(self, index, values) -> None:
        self.calls.append(("scalars", index, dict(values)))

    def close(self, complete: bool) -> None:
        self.calls.append(("close", complete))

    def discard(self) -> None:
        self.calls.append(("discard",))

    def of(self, kind: str) -> list[tuple]:
        return [call for call in self.calls if call[0] == kind]


def test_the_viewer_shows_a_frame_and_leaves_the_run_unchanged(
    tiny_sequence: Path, tiny_run
) -> None:
    run_dir = tiny_run.run_dir
    settings = ["viewer.render_every=1", "viewer.render_downscale=4", "viewer.mesh_every=1"]
    config = load_config(run_dir / "config.yaml", [*settings, "viewer.mesh_resolution=0.1"])
    device = torch.device("cpu")
    state = load_state(run_dir / "map.pt", config, device)
    field_before = {k: v.clone() for k, v in state.field.state_dict().items()}
    generator_before = state.generator.get_state().clone()
    poses_before = state.trajectory.poses.clone()
    frames = len(poses_before)
    last = frames - 1
    image = open_sequence(DataConfig(path=str(tiny_sequence)))[last]

    sink = RecordingSink()
    observer = ViewerObserver(sink, config.viewer)
    observer.on_start(RunStart(config, run_dir, state, device, "tiny", frames, False))
    pose = state.trajectory.poses[last]
    observer.on_frame(FrameDone(last, pose, True, None, True, 0.25, 0.5, frame=image))
    observer.on_mapping(MappingDone(last, (0, last), 6, torch.tensor(0.125)))
    observer.on_finish(RunEnd(True, frames, 1.0))
    observer.release()  # closed already: nothing more

    for key, value in state.field.state_dict().items():
        assert torch.equal(value, field_before[key]), key
    assert torch.equal(state.generator.get_state(), generator_before)
    assert torch.equal(state.trajectory.poses, poses_before)

    (camera,) = sink.of("camera")
    np.testing.assert_allclose(camera[2], tiny_run.poses[last], atol=1e-6)
    assert camera[3] == (60, 80, 3) and camera[4] == (60, 80)
    trajectory = sink.of("trajectory")[-1]
    np.testing.assert_allclose(trajectory[2], tiny_run.poses[:, :3, 3], atol=1e-6)
    assert trajectory[3].shape == (frames, 3)
    (rendered,) = sink.of("rendered")
    assert rendered[2] == (20, 15) and rendered[4] == (15, 20, 3)
    assert (rendered[3] > 0).mean() > 0.9
    meshes = sink.of("mesh")
    assert len(meshes) == 2 and meshes[0][2] > 0, "at the keyframe and at the end"
    scalars = {name: value for call in sink.of("scalars") for name, value in call[2].items()}
    assert scalars == {
        "time/tracking_ms": 250.0,
        "time/mapping_ms": 500.0,
        "stream/dropped_frames": 0.0,
        "mapping/loss": 0.125,
    }
    assert sink.calls[-1] == ("close", True) and len(sink.of("close")) == 1


def test_a_run_that_never_started_keeps_no_recording() -> None:
    sink = RecordingSink()
    observer = ViewerObserver(sink, ViewerConfig())
    observer.release()
    observer.release()
    assert sink.calls == [("discard",)]


def test_nothing_is_rendered_or_meshed_when_switched_off(tiny_sequence: Path, tiny_run) -> None:
    run_dir = tiny_run.run_dir
    config = load_config(run_dir / "config.yaml", ["viewer.render_every=0", "viewer.mesh_every=0"])
    state = load_state(run_dir / "map.pt", config, torch.device("cpu"))
    sink = RecordingSink()
    observer = ViewerObserver(sink, config.viewer)
    observer.on_start(RunStart(config, run_dir, state, torch.device("cpu"), "tiny", 1, False))
    observer.on_frame(FrameDone(0, state.trajectory.poses[0], False, None, True, 0.0, 0.0))
    observer.on_failure(RuntimeError("stopped"), 1)
    assert not sink.of("rendered") and not sink.of("mesh")
    assert sink.of("camera")[0][3:] == (None, None), "a frame without images shows none"
    assert sink.calls[-1] == ("close", False)


def test_without_a_viewer_option_nothing_of_the_viewer_is_imported() -> None:
    """Cost when off: `eslam run` without --viewer / --viewer-save imports no rerun and
    none of the viewer's modules, and passes no observer."""
    code = (
        "import argparse, sys, eslam.cli.runs as runs; "
        "args = argparse.Namespace(viewer=None, viewer_save=None); "
        "observers = runs.viewer(args, None, None).__enter__(); "
        "names = ('rerun', 'eslam.slam.run.viewer', 'eslam.viz.rerun_viewer', "
        "'eslam.workflows.live_viewer'); "
        "print(observers, sorted(m for m in names if m in sys.modules))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert result.stdout.strip() == "[] []"


def test_the_tracking_plots_show_the_information_where_the_tracker_computed_it():
    from eslam.slam.run.viewer import frame_scalars
    from eslam.slam.tracking.base import TrackingQuality

    pose = torch.eye(4)
    judged = TrackingQuality(4, 0.9, 0.002, False, information=0.003, degenerate_directions=1)
    values = frame_scalars(FrameDone(1, pose, True, judged, False, 0.0, 0.0))
    assert values["tracking/information"] == pytest.approx(0.003)
    assert values["tracking/residual_mm"] == pytest.approx(2.0)
    unknown = dataclasses.replace(judged, information=float("nan"))  # an old map's frames
    assert "tracking/information" not in frame_scalars(
        FrameDone(1, pose, True, unknown, False, 0.0, 0.0)
    )


def test_dropped_frames_are_the_stream_position_ahead_of_the_run_position(tiny_sequence):
    from eslam.slam.run.viewer import frame_scalars

    image = open_sequence(DataConfig(path=str(tiny_sequence)))[3]  # the stream's 4th frame
    pose = torch.eye(4)
    dropped = frame_scalars(FrameDone(1, pose, True, None, False, 0.0, 0.0, frame=image))
    assert dropped["stream/dropped_frames"] == 2.0
    assert "stream/dropped_frames" not in frame_scalars(
        FrameDone(1, pose, True, None, False, 0.0, 0.0)
    )


def test_the_viewer_shows_loop_edges_when_they_change(tiny_run) -> None:
    """With loop closure on, each loop edge joins the two frames' camera centres; they
    are sent again only when an edge was added."""
    run_dir = tiny_run.run_dir
    config = load_config(run_dir / "config.yaml", ["viewer.render_every=0", "viewer.mesh_every=0"])
    state = load_state(run_dir / "map.pt", config, torch.device("cpu"))
    last = len(state.trajectory.poses) - 1
    state.components["loops"] = {"edges": [[0, last, *np.eye(4).ravel().tolist()]]}
    sink = RecordingSink()
    observer = ViewerObserver(sink, config.viewer)
    observer.on_start(
        RunStart(config, run_dir, state, torch.device("cpu"), "tiny", last + 1, False)
    )
    pose = state.trajectory.poses[last]
    for _ in range(2):
        observer.on_frame(FrameDone(last, pose, True, None, False, 0.25, 0.0))
    (call,) = sink.of("loops")
    centres = state.trajectory.poses[[0, last], :3, 3].double().numpy()
    np.testing.assert_allclose(call[2], centres[None], atol=1e-12)
