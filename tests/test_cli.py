"""The eslam command: help, synth, inspect, and one-line errors with exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from eslam.cli import EXIT_USER_ERROR, SETTINGS_WIDTH, main
from eslam.config import config_help
from eslam.data.replica import ReplicaSequence
from eslam.io.mesh_files import read_mesh_ply, write_mesh_ply
from eslam.io.trajectory import write_tum_trajectory
from eslam.types import TriangleMesh


def _one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, f"error must be one line, got:\n{err}"
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize(
    "command",
    [[], ["synth"], ["inspect"], ["ate"], ["recon"], ["configs"], ["sweep"], ["table"]],
)
def test_help(command: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--help"])
    assert exit_info.value.code == 0
    assert "usage: eslam" in capsys.readouterr().out


def test_run_help_lists_every_setting_with_its_docstring(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["run", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    settings = out[out.index("settings (key=value after CONFIG)") :]
    assert "\n  tracking." in settings and "\n  mapping.every (" in settings
    rows = config_help()  # every key of the dataclasses, none written by hand
    every = next(row for row in rows if row.key == "mapping.every")
    assert f"mapping.every ({every.default}): {' '.join(every.doc.split()[:4])}" in settings
    for row in rows:
        assert f"\n  {row.key} ({row.default}): " in settings
    assert all(len(line) <= SETTINGS_WIDTH for line in settings.splitlines())


def test_no_command_is_one_line_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([])
    assert exit_info.value.code == EXIT_USER_ERROR
    assert "required: COMMAND" in _one_line_error(capsys)


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--size", "640by480"], "size must look like 640x480, got '640by480'"),
        (["--size", "4x4"], "size must be at least 8x8"),
        (["--frames", "0"], "expected a positive integer, got '0'"),
        (["--scene", "castle"], "invalid choice: 'castle'"),
        (["seed=3"], "unrecognized arguments: seed=3"),
        (["--trajectory", "spiral"], "invalid choice: 'spiral'"),
        (["--focal-error", "0.7"], "must be in (-0.5, 0.5), got 0.7"),
    ],
)
def test_synth_bad_arguments(
    arguments: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["synth", str(tmp_path / "out"), *arguments])
    assert exit_info.value.code == EXIT_USER_ERROR
    assert message in _one_line_error(capsys)
    assert not (tmp_path / "out").exists()


def test_synth_writes_a_readable_sequence_and_refuses_to_overwrite(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "synth"
    assert main(["synth", str(out), "--frames", "3", "--size", "64x48", "--seed", "1"]) == 0
    assert "wrote 3 frames (64x48" in capsys.readouterr().out
    sequence = ReplicaSequence(out)
    assert len(sequence) == 3 and sequence.intrinsics.size == (64, 48)
    assert (out / "mesh.ply").is_file()
    before = (out / "traj.txt").read_bytes()

    assert main(["synth", str(out), "--frames", "2", "--size", "64x48", "--seed", "2"]) == 2
    assert "already exists and is not empty" in _one_line_error(capsys)
    assert (out / "traj.txt").read_bytes() == before, "a refused run must not touch the folder"
    assert [p.name for p in tmp_path.iterdir()] == ["synth"], "no staging folder left behind"

    assert main(["synth", str(out), "--frames", "2", "--size", "64x48", "--overwrite"]) == 0
    assert len(ReplicaSequence(out)) == 2


def test_inspect_summarises(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "synth"
    assert main(["synth", str(out), "--frames", "4", "--size", "64x48"]) == 0
    capsys.readouterr()
    assert main(["inspect", str(out)]) == 0
    text = capsys.readouterr().out
    assert "frames     4" in text and "camera     64x48" in text and "path length" in text


def test_inspect_missing_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(tmp_path / "missing")]) == EXIT_USER_ERROR
    err = _one_line_error(capsys)
    assert err.startswith("eslam inspect: error: ") and "missing: folder not found" in err


def test_inspect_bad_pose_names_file_and_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "synth"
    assert main(["synth", str(out), "--frames", "3", "--size", "32x24"]) == 0
    traj = out / "traj.txt"
    rows = np.loadtxt(traj)
    rows[2, 7] = np.inf
    np.savetxt(traj, rows)
    assert main(["inspect", str(out)]) == EXIT_USER_ERROR
    err = _one_line_error(capsys)
    assert "traj.txt: line 3: pose has non-finite values" in err


def test_console_script_runs_without_traceback(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "eslam.cli", "inspect", str(tmp_path / "nope")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == EXIT_USER_ERROR
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert "nope: folder not found" in result.stderr


def _write_tum(path: Path, times: np.ndarray, positions: np.ndarray) -> None:
    poses = np.tile(np.eye(4), (len(times), 1, 1))
    poses[:, :3, 3] = positions
    write_tum_trajectory(path, times, poses)


def test_ate_command_table_json_and_run_folders(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rng = np.random.default_rng(0)
    positions = np.cumsum(rng.normal(scale=0.05, size=(20, 3)), axis=0)
    rotation = Rotation.from_rotvec([0.2, 0.5, -1.0]).as_matrix()
    _write_tum(tmp_path / "gt.txt", np.arange(20.0), positions)
    _write_tum(tmp_path / "est.txt", np.arange(20.0) + 0.003, positions @ rotation.T + 2.0)
    assert main(["ate", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt")]) == 0
    table = capsys.readouterr().out
    assert "ate_rmse_cm" in table and "pairs" in table and "20" in table

    run = tmp_path / "run"
    _write_tum(run / "trajectory_gt.txt", np.arange(20.0), positions)
    _write_tum(run / "trajectory.txt", np.arange(20.0), 2.0 * positions)
    assert main(["ate", str(run), str(run), "--align", "sim3", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["pairs"] == 20 and report["ate_rmse_cm"] < 1e-9
    assert report["scale"] == pytest.approx(0.5) and report["align"] == "sim3"
    assert report["rpe_pairs"] == 19 and report["rpe_translation_rmse_mm"] > 10  # 2x steps
    assert main(["ate", str(run), str(run), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ate_rmse_cm"] > 1.0  # se3 cannot scale


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["missing.txt", "est.txt"], "missing.txt: not found"),
        (["gt.txt", "late.txt"], "only 0 poses matched within 0.01 s"),
        (["gt.txt", "est.txt", "--align", "affine"], "invalid choice: 'affine'"),
        (["gt.txt", "est.txt", "--max-diff", "-1"], "expected a number >= 0"),
    ],
)
def test_ate_command_errors(
    arguments: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    positions = np.random.default_rng(1).normal(size=(5, 3))
    _write_tum(tmp_path / "gt.txt", np.arange(5.0), positions)
    _write_tum(tmp_path / "est.txt", np.arange(5.0), positions)
    _write_tum(tmp_path / "late.txt", np.arange(5.0) + 0.5, positions)
    paths = [str(tmp_path / a) if a.endswith(".txt") else a for a in arguments]
    try:
        status = main(["ate", *paths])
    except SystemExit as exit_info:
        status = exit_info.code
    assert status == EXIT_USER_ERROR
    assert message in _one_line_error(capsys)


def _sphere_mesh(radius: float) -> TriangleMesh:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    vertices = np.asarray(sphere.vertices)
    return TriangleMesh(vertices, np.asarray(sphere.faces), np.zeros(vertices.shape, np.uint8))


def test_recon_command_exact_and_depth_l1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_mesh_ply(tmp_path / "gt.ply", _sphere_mesh(1.0))
    write_mesh_ply(tmp_path / "run" / "mesh.ply", _sphere_mesh(1.0))
    arguments = ["recon", str(tmp_path / "run"), str(tmp_path / "gt.ply"), "--samples", "3000"]
    assert main([*arguments, "--exact", "--depth-l1", "--views", "2", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["accuracy_cm"] < 1e-9 and report["completion_ratio_pct"] == 100.0
    assert report["samples"] == 3000 and report["exact"] is True
    assert report["depth_l1_cm"] == 0.0 and report["views_used"] == 2
    assert report["rec"].endswith("mesh.ply")
    assert main(arguments) == 0
    table = capsys.readouterr().out
    assert "accuracy_cm" in table and "exact" in table and "depth_l1_cm" not in table


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["nothing.ply", "gt.ply"], "nothing.ply: not found"),
        (["empty_run", "gt.ply"], "empty_run: holds no mesh_culled.ply or mesh.ply"),
        (["gt.ply", "gt.ply", "--samples", "0"], "expected a positive integer, got '0'"),
    ],
)
def test_recon_command_errors(
    arguments: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_mesh_ply(tmp_path / "gt.ply", _sphere_mesh(1.0))
    (tmp_path / "empty_run").mkdir()
    paths = [a if a.startswith("-") or a.isdigit() else str(tmp_path / a) for a in arguments]
    try:
        status = main(["recon", *paths])
    except SystemExit as exit_info:
        status = exit_info.code
    assert status == EXIT_USER_ERROR
    assert message in _one_line_error(capsys)


@pytest.mark.realdata
def test_recon_office0_exact_against_itself_and_one_centimetre_off(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    gt_path = real_data / "replica-office0" / "office0_mesh.ply"
    options = ["--exact", "--samples", "100000", "--json"]
    assert main(["recon", str(gt_path), str(gt_path), *options]) == 0
    itself = json.loads(capsys.readouterr().out)
    assert itself["accuracy_cm"] < 1e-10 and itself["completion_cm"] < 1e-10
    assert itself["completion_ratio_pct"] == 100.0
    gt = read_mesh_ply(gt_path)
    normals = trimesh.Trimesh(gt.vertices, gt.faces, process=False).vertex_normals
    displaced = TriangleMesh(gt.vertices + 0.01 * normals, gt.faces, gt.colours)
    write_mesh_ply(tmp_path / "displaced.ply", displaced)
    assert main(["recon", str(tmp_path / "displaced.ply"), str(gt_path), *options]) == 0
    off = json.loads(capsys.readouterr().out)
    assert abs(off["accuracy_cm"] - 1.0) < 0.1 and abs(off["completion_cm"] - 1.0) < 0.1


def test_sigterm_stops_a_command_like_ctrl_c(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import os
    import signal
    import time

    import eslam.cli as cli
    from eslam.cli import resume

    def terminated(args) -> int:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the handler raises long before
        return 0

    before = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(resume, "handle", terminated)
    assert cli.main(["resume", "somewhere"]) == 130
    assert "eslam resume: interrupted" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) == before  # restored after the command


@pytest.mark.parametrize(
    ("argv", "setting"),
    [
        (["run", "configs/demo.yaml", "--format", "tum"], "data.format=tum"),
        (["run", "configs/demo.yaml", "seed=1", "--format=scannet"], "data.format=scannet"),
        (["demo", "--depth-scale", "1000"], "data.depth_scale=1000"),
    ],
)
def test_an_option_that_is_a_setting_suggests_key_value(
    argv: list[str], setting: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """`eslam run --format tum` (only inspect takes --format) was refused without saying
    that settings follow the config as data.format=tum."""
    assert main(argv) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert setting in err and f"eslam {argv[0]} --help" in err and "Traceback" not in err


def test_configs_lists_the_packaged_names_from_any_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["configs"]) == 0
    names = {line.split()[0] for line in capsys.readouterr().out.splitlines()[1:]}
    assert {"demo", "cpu", "replica/room0", "tum/fr1_desk", "scannet/scene0000"} <= names
    # and eslam run takes such a name from here (it stops at the missing data, exit 2)
    assert main(["run", "replica/room0", "--out", str(tmp_path / "run")]) == EXIT_USER_ERROR
    assert "data.path is not set" in capsys.readouterr().err
