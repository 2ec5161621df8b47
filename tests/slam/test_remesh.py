"""`eslam mesh` / remesh_run: re-extract mesh.ply from a saved run folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import load_config
from eslam.io.mesh_files import read_mesh_ply
from eslam.slam.run.remesh import remesh_run
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
from eslam.workflows.demo import DEMO_CONFIG

# A few frames, coarse planes and few iterations: a real run folder in seconds.
TINY = [
    "tracking.render.rays=100",
    "tracking.border=4",
    "tracking.render.iterations=2",
    "mapping.rays=300",
    "mapping.every=2",
    "mapping.window=3",
    "mapping.iterations=2",
    "mapping.first_iterations=40",
    "mapping.first_lr_factor=5.0",
    "mapping.first_warm_start=none",
    "render.samples_stratified=8",
    "render.samples_surface=4",
    "output.progress=false",
    "output.mesh_resolution=0.1",
    "field.geometry_resolution=[0.24, 0.12]",
    "field.appearance_resolution=[0.24, 0.12]",
]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("remesh")
    data = root / "data"
    write_synthetic_sequence(data, SynthConfig(frames=3, width=64, height=48, seed=1))
    overrides = [f"data.path={data}", f"scene.bound={read_synthetic_bound(data)}", *TINY]
    return run_slam(load_config(DEMO_CONFIG, overrides), root / "run").run_dir


def test_cli_mesh_rewrites_mesh_ply(run_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = read_mesh_ply(run_dir / "mesh.ply")
    assert main(["mesh", str(run_dir), "--resolution", "0.05"]) == 0
    assert "mesh.ply" in capsys.readouterr().out
    after = read_mesh_ply(run_dir / "mesh.ply")
    assert len(after.faces) > 2 * len(before.faces) > 0, "a finer grid, many more faces"
    config = load_config(run_dir / "config.yaml")
    bound = np.asarray(config.scene.bound)
    assert (after.vertices >= bound[:, 0] - 0.25).all()
    assert (after.vertices <= bound[:, 1] + 0.25).all()
    result = remesh_run(run_dir)  # the run's own resolution again
    assert result.resolution == 0.1 and result.faces == len(before.faces)
    assert len(read_mesh_ply(run_dir / "mesh.ply").faces) == len(before.faces)


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--resolution", "0"], "expected a positive number, got '0'"),
        (["--device", "cuda:7"], "device 'cuda:7'"),
    ],
)
def test_cli_mesh_bad_arguments(
    run_dir: Path, arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    if message.startswith("device") and torch.cuda.device_count() > 7:
        pytest.skip("this machine has a cuda:7")
    try:
        code = main(["mesh", str(run_dir), *arguments])
    except SystemExit as exit_info:  # argparse rejects the value itself
        code = exit_info.code
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_cli_mesh_without_a_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mesh", str(tmp_path)]) == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "config.yaml: not found" in err and "\n" not in err
