"""The eslam command: help, synth, inspect, and one-line errors with exit status 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eslam.cli import EXIT_USER_ERROR, main
from eslam.data.replica import ReplicaSequence


def _one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, f"error must be one line, got:\n{err}"
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize("command", [[], ["synth"], ["inspect"]])
def test_help(command: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--help"])
    assert exit_info.value.code == 0
    assert "usage: eslam" in capsys.readouterr().out


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
