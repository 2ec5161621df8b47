"""The single-writer lock of a run folder: one ``eslam run`` / ``eslam resume`` at a time.

Two runs writing the same folder would replace each other's map.pt, trajectory and
log in turn, leaving outputs that belong to neither. A run therefore holds
``RUN/run.lock`` while it writes: a small JSON file naming the process (pid, host,
start time). It is created with a hard link from a complete temporary file, which is
atomic and fails when the lock exists, so no reader ever sees a half-written lock and
two runs cannot both create it.

A lock whose process is gone (killed with SIGKILL, a crashed machine) is stale: on the
same host a dead pid is detected and the lock taken over (the caller logs it). A lock
from another host cannot be checked from here, so it is refused with the fix (delete
the file once that run is known to be gone).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from eslam.errors import InputError

LOCK_NAME = "run.lock"
"""File name of the lock inside a run folder."""


@dataclass(frozen=True)
class LockOwner:
    """Who holds a run folder's lock.

    Attributes:
        pid: process id of the run.
        host: host name of the machine it runs on.
        started: when it took the lock (seconds since the epoch).
    """

    pid: int
    host: str
    started: float

    def describe(self) -> str:
        """``pid 123 on host, since 2026-12-01 20:44:50``, for messages."""
        since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.started))
        return f"pid {self.pid} on {self.host}, since {since}"


@dataclass(frozen=True)
class HeldLock:
    """A lock this process holds.

    Attributes:
        path: the lock file.
        owner: this process, as written in the file.
        replaced: the stale owner whose lock was taken over, or None.
    """

    path: Path
    owner: LockOwner
    replaced: LockOwner | None = None


def this_process() -> LockOwner:
    """The current process as a lock owner."""
    return LockOwner(pid=os.getpid(), host=socket.gethostname(), started=time.time())


def read_owner(path: Path) -> LockOwner | None:
    """The owner written in the lock ``path``; None when it is missing or unreadable."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return LockOwner(int(data["pid"]), str(data["host"]), float(data["started"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def process_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (signal 0 checks, sends nothing)."""
    if pid <= 0:
        return False
    if os.name == "nt":  # signal 0 is CTRL_C_EVENT there: never probe, assume it lives
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, owned by someone else
        return True
    except OSError:
        return True
    return True


def is_stale(owner: LockOwner | None) -> bool:
    """Whether a lock's process is known to be gone: same host and a dead pid.

    An unreadable lock file is stale too (a lock is complete when it appears, so only a
    damaged file reads as nothing). A lock of another host is never stale here.
    """
    if owner is None:
        return True
    return owner.host == socket.gethostname() and not process_alive(owner.pid)


def _create(path: Path, owner: LockOwner) -> bool:
    """Create the lock ``path`` holding ``owner``; False when it exists already.

    The content goes to a temporary file first and is hard-linked into place, so the
    lock appears complete or not at all (``eslam.atomic`` replaces, which a lock must not).
    """
    text = json.dumps({"pid": owner.pid, "host": owner.host, "started": owner.started}) + "\n"
    descriptor, name = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    tmp = Path(name)
    try:
        with os.fdopen(descriptor, "w", encoding="utf-8") as handle:
            handle.write(text)
        try:
            os.link(tmp, path)
        except FileExistsError:
            return False
        except OSError as error:  # a file system without hard links: exclusive create
            if error.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
                raise
            return _create_exclusive(path, text)
    finally:
        tmp.unlink(missing_ok=True)
    return True


def _create_exclusive(path: Path, text: str) -> bool:
    try:
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        return False
    with os.fdopen(descriptor, "w", encoding="utf-8") as handle:
        handle.write(text)
    return True


def acquire(run_dir: Path, command: str) -> HeldLock:
    """Take the lock of ``run_dir`` (which must exist) for this process.

    Args:
        run_dir: the run folder.
        command: what to call the refused command in the message (``eslam run``).

    Raises:
        InputError: another live run holds the folder (the message names it and the fix).
    """
    path = Path(run_dir) / LOCK_NAME
    me = this_process()
    replaced = None
    for _ in range(3):
        try:
            created = _create(path, me)
        except OSError as error:  # a read-only folder, a full disk: nothing was written
            raise InputError(
                path,
                f"cannot create the run's lock ({error.strerror or error})",
                "check that the run folder is writable and its disk has space",
            ) from None
        if created:
            return HeldLock(path, me, replaced)
        owner = read_owner(path)
        if not is_stale(owner):
            break
        replaced = owner or LockOwner(0, "unknown", 0.0)
        # move the stale lock aside (atomic: of two takers only one moves this file)
        with contextlib.suppress(FileNotFoundError):
            os.replace(path, path.with_name(f"{LOCK_NAME}.stale-{me.pid}"))
            os.unlink(path.with_name(f"{LOCK_NAME}.stale-{me.pid}"))
    owner = read_owner(path)
    holder = owner.describe() if owner is not None else "another process"
    if owner is not None and owner.host != socket.gethostname():
        fix = f"wait for it to finish; if that run is gone, delete {path}"
    else:
        fix = (
            f"wait for it to finish or stop it, or choose another folder for {command}; "
            f"if no such run is going (its pid reused), delete {path}"
        )
    raise InputError(Path(run_dir), f"a run is still writing this folder ({holder})", fix)


def release(lock: HeldLock) -> None:
    """Remove the lock file if it is still this process's (never another run's)."""
    owner = read_owner(lock.path)
    if owner is not None and (owner.pid, owner.host) == (lock.owner.pid, lock.owner.host):
        lock.path.unlink(missing_ok=True)


@contextlib.contextmanager
def run_folder_lock(run_dir: Path, command: str) -> Iterator[HeldLock]:
    """Hold the lock of ``run_dir`` inside the block; released on any exit (errors, Ctrl-C).

    Raises:
        InputError: another live run holds the folder.
    """
    lock = acquire(run_dir, command)
    try:
        yield lock
    finally:
        release(lock)
