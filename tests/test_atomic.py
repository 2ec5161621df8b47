"""Atomic writes: a failure leaves the earlier file or folder exactly as it was."""

from __future__ import annotations

from pathlib import Path

import pytest

from eslam.atomic import atomic_directory, atomic_path, write_bytes, write_text, write_with


def test_write_text_and_bytes(tmp_path: Path) -> None:
    write_text(tmp_path / "a" / "b.txt", "hello")
    write_bytes(tmp_path / "c.bin", b"\x00\x01")
    assert (tmp_path / "a" / "b.txt").read_text() == "hello"
    assert (tmp_path / "c.bin").read_bytes() == b"\x00\x01"


def test_failed_write_keeps_old_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "metrics.json"
    write_text(target, "old")

    def crash(tmp: Path) -> None:
        tmp.write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_with(target, crash)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.json"]


def test_temporary_keeps_suffix(tmp_path: Path) -> None:
    with atomic_path(tmp_path / "mesh.ply") as tmp:
        assert tmp.suffix == ".ply" and tmp.parent == tmp_path
        tmp.write_text("ply")
    assert (tmp_path / "mesh.ply").read_text() == "ply"


def test_directory_published_only_on_success(tmp_path: Path) -> None:
    target = tmp_path / "run"
    with pytest.raises(RuntimeError), atomic_directory(target) as staging:
        (staging / "x").write_text("1")
        raise RuntimeError("interrupted")
    assert not target.exists() and list(tmp_path.iterdir()) == []

    with atomic_directory(target) as staging:
        (staging / "x").write_text("2")
    assert (target / "x").read_text() == "2"


def test_directory_refuses_non_empty_without_overwrite(tmp_path: Path) -> None:
    target = tmp_path / "run"
    target.mkdir()
    (target / "keep").write_text("earlier output")
    with pytest.raises(FileExistsError), atomic_directory(target):
        pass
    assert (target / "keep").read_text() == "earlier output"

    with pytest.raises(ValueError), atomic_directory(target, overwrite=True) as staging:
        (staging / "new").write_text("1")
        raise ValueError("failed half-way")
    assert [p.name for p in target.iterdir()] == ["keep"], "a failed overwrite keeps the old folder"

    with atomic_directory(target, overwrite=True) as staging:
        (staging / "new").write_text("1")
    assert [p.name for p in target.iterdir()] == ["new"]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_empty_existing_directory_is_fine(tmp_path: Path) -> None:
    (tmp_path / "run").mkdir()
    with atomic_directory(tmp_path / "run") as staging:
        (staging / "x").write_text("1")
    assert (tmp_path / "run" / "x").exists()


def test_written_files_get_ordinary_permissions(tmp_path: Path) -> None:
    import os

    write_text(tmp_path / "a.txt", "x")
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o666 & ~mask


def test_published_directory_gets_ordinary_permissions(tmp_path: Path) -> None:
    import os

    with atomic_directory(tmp_path / "run") as staging:
        (staging / "x").write_text("1")
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "run").stat().st_mode & 0o777 == 0o777 & ~mask
