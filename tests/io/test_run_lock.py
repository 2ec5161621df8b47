"""The single-writer lock of a run folder: taken, refused while its run lives, taken over
when its process is gone, released on every exit."""

from __future__ import annotations

import errno
import json
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from eslam.errors import InputError
from eslam.io.run_lock import (
    LOCK_NAME,
    LockOwner,
    acquire,
    is_stale,
    read_owner,
    release,
    run_folder_lock,
)


def _dead_pid() -> int:
    """The pid of a process that has exited (and was reaped)."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def _write_lock(folder: Path, pid: int, host: str) -> None:
    (folder / LOCK_NAME).write_text(json.dumps({"pid": pid, "host": host, "started": 0.0}))


def test_the_lock_names_this_process_and_is_released(tmp_path: Path) -> None:
    with run_folder_lock(tmp_path, "eslam run") as lock:
        owner = read_owner(tmp_path / LOCK_NAME)
        assert owner == lock.owner and lock.replaced is None
        assert owner.host == socket.gethostname()
        assert not is_stale(owner)
    assert not (tmp_path / LOCK_NAME).exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no temporary file left


def test_a_live_run_holds_the_folder(tmp_path: Path) -> None:
    with run_folder_lock(tmp_path, "eslam run"):
        with pytest.raises(InputError, match=r"a run is still writing this folder \(pid") as e:
            acquire(tmp_path, "eslam resume")
        assert "\n" not in str(e.value) and "eslam resume" in str(e.value)
    assert acquire(tmp_path, "eslam resume") is not None  # free again


def test_the_lock_is_released_on_an_error_and_on_ctrl_c(tmp_path: Path) -> None:
    for error in (ValueError("boom"), KeyboardInterrupt()):
        with pytest.raises(type(error)), run_folder_lock(tmp_path, "eslam run"):
            raise error
        assert not (tmp_path / LOCK_NAME).exists()


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path: Path) -> None:
    dead = _dead_pid()
    _write_lock(tmp_path, dead, socket.gethostname())
    lock = acquire(tmp_path, "eslam run")
    assert lock.replaced == LockOwner(dead, socket.gethostname(), 0.0)
    assert read_owner(tmp_path / LOCK_NAME) == lock.owner
    release(lock)
    assert not (tmp_path / LOCK_NAME).exists()


def test_a_damaged_lock_is_stale(tmp_path: Path) -> None:
    (tmp_path / LOCK_NAME).write_text("not json")
    assert acquire(tmp_path, "eslam run").replaced is not None


def test_a_lock_of_another_host_is_refused_with_the_fix(tmp_path: Path) -> None:
    _write_lock(tmp_path, 1, "another-host.example")
    with pytest.raises(InputError, match=r"on another-host.example.*delete .*run.lock"):
        acquire(tmp_path, "eslam run")
    assert read_owner(tmp_path / LOCK_NAME).host == "another-host.example"


def test_release_leaves_another_runs_lock(tmp_path: Path) -> None:
    lock = acquire(tmp_path, "eslam run")
    _write_lock(tmp_path, 1, "another-host.example")  # taken over by someone else
    release(lock)
    assert (tmp_path / LOCK_NAME).exists()


def test_a_read_only_folder_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(InputError, match=r"run.lock: cannot create the run's lock") as caught:
        acquire(tmp_path, "eslam run")
    message = str(caught.value)
    assert "\n" not in message and "Read-only file system" in message and "writable" in message
