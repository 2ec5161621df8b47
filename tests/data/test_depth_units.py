"""The depth-unit check: a clearly wrong scale is refused at the start of a run, on
every keyframe and by `eslam inspect`, while every real and synthetic sequence passes
(issue 15: depth / 10 and data.depth_scale off by 6.5x were accepted silently)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import DataConfig, load_config
from eslam.data import open_sequence
from eslam.data.depth_units import (
    DepthCheck,
    DepthSpread,
    sequence_depth_file,
    sequence_depth_scale,
)
from eslam.data.inspect import inspect_sequence
from eslam.data.replica import write_replica_sequence
from eslam.data.source import IterableSource
from eslam.errors import InputError, RunStopped
from eslam.slam.session import preflight, run_slam
from eslam.synthetic import SynthConfig, generate_sequence, read_synthetic_bound
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY

REAL = [
    ("replica-room0", "replica", 6553.5),
    ("replica-office0", "replica", 6553.5),
    ("7scenes-redkitchen", "sevenscenes", 1000.0),
]
"""The real sequences under ESLAM_TEST_DATA: folder, layout, correct depth scale."""


def _open(real_data: Path, folder: str, layout: str, scale: float | None = None):
    return open_sequence(DataConfig(format=layout, path=str(real_data / folder), depth_scale=scale))


@pytest.mark.parametrize(("folder", "layout", "scale"), REAL)
def test_real_sequences_pass(real_data: Path, folder: str, layout: str, scale: float) -> None:
    sequence = _open(real_data, folder, layout)
    assert sequence_depth_scale(sequence) == scale
    check = DepthCheck.for_run(scale, None)
    for index in range(0, len(sequence), 5):
        assert check.problem(sequence[index].depth, sequence.root, f"frame {index}") is None
    preflight(sequence, check)


@pytest.mark.parametrize(("folder", "layout", "correct"), REAL)
@pytest.mark.parametrize("factor", [10.0, 1 / 10, 6.5535, 1 / 6.5535, 5.0, 1 / 5])
def test_real_sequences_with_a_wrong_scale_are_refused(
    real_data: Path, folder: str, layout: str, correct: float, factor: float
) -> None:
    """data.depth_scale = factor x the correct one: depth 1 / factor x the truth."""
    wrong = correct * factor
    sequence = _open(real_data, folder, layout, wrong)
    check = DepthCheck.for_run(wrong, None)
    try:
        frame = sequence[0]
    except InputError as impossible:  # beyond any sensor: the reader's own check refuses it
        assert f"depth scale {correct:g} would give" in str(impossible)
        return
    spread = DepthSpread.of(frame.depth)
    assert spread is not None
    error = check.problem(frame.depth, sequence_depth_file(sequence, 0), "frame 0")
    if factor == 5.0 and folder == "replica-room0":
        # the documented limit (PLAUSIBLE_FAR_M): room0 / 5 (median 0.54 m, far end
        # 0.85 m) is what a close-up view looks like, so it passes
        assert error is None
        return
    assert error is not None, (folder, factor, spread)
    message = str(error)
    assert message.startswith(str(sequence_depth_file(sequence, 0)) + ": frame 0: median depth")
    assert "\n" not in message and "not in metres" in message
    assert f"data.depth_scale={correct:g} " in message  # the correct scale is one suggestion


def test_sequence_depth_file_sees_through_a_frame_selection(real_data: Path) -> None:
    config = DataConfig(format="replica", path=str(real_data / "replica-room0"), start=3, stride=2)
    sequence = open_sequence(config)
    assert sequence_depth_file(sequence, 1).name == "depth000005.png"
    assert sequence_depth_scale(sequence) == 6553.5


def test_synthetic_sequences_pass() -> None:
    check = DepthCheck.for_run(None, None)
    for seed in range(4):
        for frame in generate_sequence(SynthConfig(frames=10, width=80, height=60, seed=seed)):
            assert check.problem(frame.depth, "synth", "frame") is None


def test_a_median_beyond_the_scene_bound_is_refused() -> None:
    depth = np.full((10, 10), 3.0, dtype=np.float32)
    small_room = [[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]]  # diagonal 1.73 m
    error = DepthCheck.for_run(1000.0, small_room).problem(depth, "d.png", "frame 0")
    assert error is not None and "scene bound's diagonal (1.73 m)" in str(error)
    assert DepthCheck.for_run(1000.0, [[0, 4], [0, 4], [0, 4]]).problem(depth, "d", "f") is None


def test_no_valid_depth_and_a_disabled_check_pass() -> None:
    tiny = np.full((4, 4), 0.05, dtype=np.float32)
    assert DepthCheck.for_run(None, None).problem(np.zeros((4, 4)), "d", "f") is None
    assert DepthCheck(enabled=False).problem(tiny, "d", "f") is None
    error = DepthCheck.for_run(None, None).problem(tiny, "stream", "frame 3")
    assert error is not None and "off by a factor of" in str(error)


@pytest.fixture(scope="module")
def depth_over_ten(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A synthetic sequence whose depth files hold a tenth of the true depth."""
    frames = [
        dataclasses.replace(f, depth=f.depth / np.float32(10))
        for f in generate_sequence(SynthConfig(frames=4, width=80, height=60, seed=3))
    ]
    root = tmp_path_factory.mktemp("over_ten") / "data"
    write_replica_sequence(root, frames)
    return root


def test_run_on_depth_over_ten_is_refused_before_writing(
    depth_over_ten: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    args = ["run", str(DEMO_CONFIG), "--data", str(depth_over_ten), "--out", str(out), *TINY]
    assert main(args) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{depth_over_ten / 'results' / 'depth000000.png'}: frame 0: median depth" in err
    assert "data.depth_scale=655.35 " in err  # 10x smaller than Replica's 6553.5
    assert "data.depth_check=false" in err  # the way out for depth that is right
    assert not out.exists()


def test_data_depth_check_false_lets_a_close_range_capture_run(
    depth_over_ten: Path, tmp_path: Path
) -> None:
    from eslam.config import load_config
    from eslam.slam.session import run_slam

    overrides = [f"data.path={depth_over_ten}", *TINY, "output.mesh=false"]
    config = load_config(DEMO_CONFIG, [*overrides, "data.depth_check=false"])
    result = run_slam(config, tmp_path / "run", stop_after=1)
    assert result.metrics["frames"] == 1


def test_inspect_reports_depth_over_ten(depth_over_ten: Path, capsys) -> None:
    summary = inspect_sequence(open_sequence(DataConfig(path=str(depth_over_ten))))
    assert summary.implausible_frames == 4 and isinstance(summary.depth_problem, InputError)
    assert main(["inspect", str(depth_over_ten)]) == EXIT_USER_ERROR
    captured = capsys.readouterr()
    assert "depth NOT in metres on 4 of 4 frames" in captured.out
    assert captured.err.count("\n") == 1 and "not in metres" in captured.err
    # the right scale fixes it
    assert main(["inspect", str(depth_over_ten), "--depth-scale", "655.35"]) == 0
    assert "depth plausibly in metres on every frame" in capsys.readouterr().out


def test_a_keyframe_whose_depth_changes_unit_stops_the_run(tmp_path: Path) -> None:
    """A live source is checked on every keyframe (mapping.every=3: frames 0, 3, 6 ...)."""
    scene = SynthConfig(frames=8, width=80, height=60, seed=3)
    frames = list(generate_sequence(scene))
    frames[6:] = [dataclasses.replace(f, depth=f.depth * np.float32(10)) for f in frames[6:]]
    data = tmp_path / "data"
    write_replica_sequence(data, frames[:1])
    bound = read_synthetic_bound_of(scene)
    config = load_config(DEMO_CONFIG, [f"scene.bound={bound}", *TINY])
    source = IterableSource(frames[0].intrinsics, iter(frames), name="camera")
    with pytest.raises(RunStopped) as caught:
        run_slam(config, tmp_path / "run", source=source)
    message = str(caught.value)
    assert message.startswith("camera: frame 6 (a keyframe): median depth")
    assert "not in metres" in message and "stopped after 6 frames" in message


def read_synthetic_bound_of(scene: SynthConfig) -> str:
    from eslam.synthetic import build_scene, scene_bound

    return str([list(pair) for pair in scene_bound(build_scene(scene.scene, scene.seed))])


def test_the_tiny_sequence_passes(tiny_sequence: Path) -> None:
    bound = read_synthetic_bound(tiny_sequence)
    sequence = open_sequence(DataConfig(path=str(tiny_sequence)))
    preflight(sequence, DepthCheck.for_run(sequence_depth_scale(sequence), bound))
    assert inspect_sequence(sequence).depth_problem is None
