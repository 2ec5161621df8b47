"""Failed writes (disk full, read-only, no permission, /proc or /sys) are one line naming
the file and the fix, exit status 2, and leave the earlier file intact (issue 15)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
import torch

from eslam import atomic
from eslam.cli import EXIT_USER_ERROR, main
from eslam.errors import ESLAMError, OutputError, output_error
from eslam.io.checkpoint import load_checkpoint, save_checkpoint


def _failing(code: int):
    def fail(*args, **kwargs):
        raise OSError(code, os.strerror(code))

    return fail


@pytest.mark.parametrize(
    ("code", "phrase"),
    [
        (errno.ENOSPC, "no space left on the device"),
        (errno.EROFS, "the file system is read-only"),
        (errno.EACCES, "permission denied"),
    ],
)
def test_a_failed_atomic_write_names_the_file_and_keeps_the_old_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, code: int, phrase: str
) -> None:
    target = tmp_path / "metrics.json"
    atomic.write_text(target, "old\n")
    monkeypatch.setattr(Path, "write_text", _failing(code))
    with pytest.raises(OutputError) as caught:
        atomic.write_text(target, "new\n")
    message = str(caught.value)
    assert message.startswith(f"{target}: {phrase}") and "\n" not in message
    assert "unchanged" in message
    assert isinstance(caught.value, ESLAMError)
    monkeypatch.undo()
    assert target.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]  # no temporary left


def test_a_read_only_folder_fails_before_the_temporary_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(atomic.tempfile, "mkstemp", _failing(errno.EROFS))
    with pytest.raises(OutputError, match="read-only"):
        atomic.write_bytes(tmp_path / "mesh.ply", b"x")


def test_torch_save_on_a_full_disk_is_named_and_keeps_the_previous_map(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """torch.save's zip writer reports a full disk as "unexpected pos" (no errno)."""
    path = tmp_path / "map.pt"
    save_checkpoint(path, {"frames": 4})

    def full_disk(payload, tmp) -> None:
        Path(tmp).write_bytes(b"PK\x03\x04 half a zip")
        raise RuntimeError("[enforce fail at inline_container.cc:626] . unexpected pos 64 vs 40")

    monkeypatch.setattr(torch, "save", full_disk)
    with pytest.raises(OutputError) as caught:
        save_checkpoint(path, {"frames": 8})
    message = str(caught.value)
    assert message.startswith(f"{path}: writing failed, most likely the disk is full")
    assert "MB free" in message and "unexpected pos" in message and "\n" not in message
    monkeypatch.undo()
    assert load_checkpoint(path)["frames"] == 4
    assert [p.name for p in tmp_path.iterdir()] == ["map.pt"]


def test_other_errors_are_not_disguised() -> None:
    assert output_error(RuntimeError("shape mismatch"), "x") is None
    assert output_error(OSError(errno.EIO, "I/O error"), "/tmp/x") is None
    assert output_error(ValueError("no"), "/tmp/x") is None


@pytest.mark.parametrize("folder", ["/proc/eslam-run", "/sys/eslam/run"])
def test_writing_under_proc_or_sys_is_refused(folder: str) -> None:
    with pytest.raises(OutputError, match="kernel file system"):
        atomic.write_text(Path(folder) / "x.txt", "x")
    with pytest.raises(OutputError, match="kernel file system"), atomic.atomic_directory(folder):
        pass


@pytest.mark.parametrize("out", ["/proc/eslam-run", "/sys/eslam/run"])
def test_run_out_under_proc_or_sys_is_one_line_exit_2(
    tiny_sequence: Path, out: str, capsys: pytest.CaptureFixture
) -> None:
    """Issue 15: `--out` under /proc or /sys was a traceback."""
    from eslam.workflows.demo import DEMO_CONFIG

    code = main(["run", str(DEMO_CONFIG), "--data", str(tiny_sequence), "--out", out])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "kernel file system" in err and out.split("/")[1] in err


@pytest.mark.skipif(
    hasattr(os, "geteuid") and os.geteuid() == 0,
    reason="root ignores file permissions, so a chmod'ed folder cannot make a write fail",
)
def test_a_folder_without_write_permission(tmp_path: Path, capsys) -> None:
    folder = tmp_path / "locked"
    folder.mkdir()
    atomic.write_text(folder / "report.md", "old\n")
    folder.chmod(0o555)
    try:
        with pytest.raises(OutputError, match="permission denied") as caught:
            atomic.write_text(folder / "report.md", "new\n")
        assert "chmod" in str(caught.value)
        assert (folder / "report.md").read_text() == "old\n"
        assert main(["synth", str(folder / "seq"), "--frames", "1", "--size", "16x16"]) == 2
        assert "permission denied" in capsys.readouterr().err
    finally:
        folder.chmod(0o755)
