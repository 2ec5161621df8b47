"""A run, a resume and `eslam mesh` whose outputs cannot be written: one line, exit 2,
the earlier map.pt / mesh.ply intact, and the run resumable (issue 15)."""

from __future__ import annotations

import errno
import logging
import os
import shutil
from pathlib import Path

import pytest
import torch

from eslam.cli import EXIT_USER_ERROR, main
from eslam.synthetic import read_synthetic_bound
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY, TINY_FRAMES


def _run_args(sequence: Path, out: Path) -> list[str]:
    bound = read_synthetic_bound(sequence)
    return ["run", str(DEMO_CONFIG), "--data", str(sequence), "--out", str(out),
            f"scene.bound={bound}", *TINY]  # fmt: skip


def _one_line(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_disk_full_at_a_checkpoint_keeps_the_previous_map_and_resumes(
    tiny_sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """Issue 15: a full disk was a torch "unexpected pos" traceback that never said space."""
    out = tmp_path / "run"
    real_save = torch.save
    saved: list[bytes] = []

    def fills_the_disk(payload, tmp) -> None:
        if not saved:  # the first checkpoint (frame 4) fits
            real_save(payload, tmp)
            saved.append(Path(tmp).read_bytes())
            return
        Path(tmp).write_bytes(b"PK\x03\x04 truncated")
        raise RuntimeError("[enforce fail at inline_container.cc:626] . unexpected pos 90 vs 77")

    monkeypatch.setattr(torch, "save", fills_the_disk)
    assert main(_run_args(tiny_sequence, out)) == EXIT_USER_ERROR
    err = _one_line(capsys)
    assert f"{out / 'map.pt'}: writing failed, most likely the disk is full" in err
    assert "the run stopped after 4 frames" in err and f"eslam resume {out}" in err
    assert (out / "map.pt").read_bytes() == saved[0]  # intact: the previous checkpoint
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporaries
    monkeypatch.undo()
    assert main(["resume", str(out)]) == 0  # space freed: nothing was lost
    rows = (out / "trajectory.txt").read_text().splitlines()
    assert len([row for row in rows if not row.startswith("#")]) == TINY_FRAMES


def test_resume_in_a_read_only_folder_is_one_line(
    tiny_sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """Issue 15: a read-only run folder made `eslam resume` a traceback."""
    out = tmp_path / "run"
    assert main([*_run_args(tiny_sequence, out), "output.checkpoint_every=100"]) == 0
    capsys.readouterr()
    before = (out / "map.pt").read_bytes()

    def read_only(filename, *args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(filename))

    monkeypatch.setattr(logging, "FileHandler", read_only)  # log.txt opened for appending
    assert main(["resume", str(out)]) == EXIT_USER_ERROR
    err = _one_line(capsys)
    assert f"{out / 'log.txt'}: the file system is read-only" in err
    assert (out / "map.pt").read_bytes() == before


def test_mesh_on_a_full_disk_keeps_the_earlier_mesh(
    tiny_run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """Issue 15: `eslam mesh` on a full disk was a traceback."""
    import trimesh

    run = tmp_path / "run"
    shutil.copytree(tiny_run.run_dir, run)
    before = (run / "mesh.ply").read_bytes()

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(trimesh.Trimesh, "export", full)
    assert main(["mesh", str(run), "--resolution", "0.1"]) == EXIT_USER_ERROR
    err = _one_line(capsys)
    assert f"{run / 'mesh.ply'}: no space left on the device" in err and "MB free" in err
    assert (run / "mesh.ply").read_bytes() == before
