"""User-facing errors: one line that names what is wrong and how to fix it.

The CLI prints ``str(error)`` of any :class:`ESLAMError` on one line and exits with
status 2, so every message must be complete without a traceback.
"""

from __future__ import annotations

import errno
import shutil
from pathlib import Path


class ESLAMError(Exception):
    """Base class of every error a user can cause (bad input, bad config, bad argument)."""


class InputError(ESLAMError):
    """A file or folder given to eslam is missing, unreadable or inconsistent.

    Args:
        path: the file or folder at fault.
        problem: what is wrong with it, as a sentence fragment.
        fix: what the user can do about it (optional).
    """

    def __init__(self, path: str | Path, problem: str, fix: str | None = None) -> None:
        self.path = Path(path)
        self.problem = problem
        self.fix = fix
        message = f"{self.path}: {problem}"
        if fix:
            message += f" ({fix})"
        super().__init__(message)


class OutputError(ESLAMError):
    """eslam could not write one of its outputs (disk full, read-only, no permission).

    Raised by the atomic writers (:mod:`eslam.atomic`), which leave the earlier version
    of the file in place, so the message can promise that nothing was corrupted.

    Args:
        path: the file or folder eslam was writing.
        problem: what went wrong, as a sentence fragment.
        fix: what the user can do about it.
    """

    def __init__(self, path: str | Path, problem: str, fix: str) -> None:
        self.path = Path(path)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.path}: {problem} ({fix})")


VIRTUAL_FILE_SYSTEMS = (Path("/proc"), Path("/sys"))
"""Kernel file systems: nothing eslam writes belongs there (writes fail oddly or worse)."""

DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)})
READ_ONLY_ERRNOS = frozenset({errno.EROFS})
PERMISSION_ERRNOS = frozenset({errno.EACCES, errno.EPERM})

TORCH_WRITE_FAILURES = ("unexpected pos", "PytorchStreamWriter failed", "file write failed")
"""Phrases of torch.save's RuntimeError when the file cannot be written: its zip writer
loses the OS error (on a full disk it reports "unexpected pos N vs M")."""

_KEEP = "the earlier version of the file, if any, is unchanged"


def virtual_location(path: str | Path) -> Path | None:
    """The kernel file system (/proc, /sys) ``path`` lies in, or None."""
    absolute = Path(path).absolute()
    for root in VIRTUAL_FILE_SYSTEMS:
        if absolute == root or root in absolute.parents:
            return root
    return None


def refuse_virtual_location(path: str | Path) -> None:
    """Raise OutputError if ``path`` lies under /proc or /sys (before anything is written)."""
    root = virtual_location(path)
    if root is not None:
        raise OutputError(
            path,
            f"is under {root}, a kernel file system, not a place for output",
            "choose an output folder on a disk",
        )


def output_error(error: BaseException, path: str | Path) -> OutputError | None:
    """The one-line OutputError for a failed write of ``path``, or None if ``error`` is
    not a write failure a user can fix (a bug, which should keep its traceback).

    Args:
        error: what the write raised: an OSError (ENOSPC, EDQUOT, EROFS, EACCES, EPERM,
            or any OSError under /proc or /sys) or torch.save's RuntimeError on a full disk.
        path: the file or folder being written (named in the message).
    """
    root = virtual_location(path)
    if root is not None and isinstance(error, OSError):
        return OutputError(
            path,
            f"is under {root}, a kernel file system, not a place for output",
            "choose an output folder on a disk",
        )
    if isinstance(error, OSError) and error.errno in DISK_FULL_ERRNOS:
        return OutputError(
            path,
            f"no space left on the device{_free_space(path)}",
            f"free some space or write to another disk; {_KEEP}",
        )
    if isinstance(error, OSError) and error.errno in READ_ONLY_ERRNOS:
        return OutputError(
            path,
            "the file system is read-only",
            f"write to a folder on a writable disk (--out), or remount it; {_KEEP}",
        )
    if isinstance(error, OSError) and error.errno in PERMISSION_ERRNOS:
        return OutputError(
            path,
            "permission denied",
            f"make {Path(path).parent} writable (chmod u+w) or write somewhere else; {_KEEP}",
        )
    text = str(error)
    if isinstance(error, RuntimeError) and any(p in text for p in TORCH_WRITE_FAILURES):
        detail = text.strip().splitlines()[0] if text.strip() else ""
        return OutputError(
            path,
            f"writing failed, most likely the disk is full{_free_space(path)} "
            f"(torch: {detail.strip(' .')})",
            f"free some space or write to another disk; {_KEEP}",
        )
    return None


def _free_space(path: str | Path) -> str:
    """ ", N MB free" on the disk of ``path`` (its nearest existing folder), or ""."""
    folder = Path(path).absolute()
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return ""
    return f", {free / 1e6:.0f} MB free"


class ConfigError(ESLAMError):
    """A configuration file or a command-line override is invalid."""


class RunStopped(ESLAMError):
    """A run stopped on an error after some frames were saved: it can be resumed.

    The message is the cause's, followed by what was saved and how to continue.

    Args:
        cause: the error that stopped the run (an ESLAMError's message is kept as is).
        frames: frames completed and saved in the run folder.
        run_dir: the run folder.
        resumable: False for a real-time run (``eslam resume`` refuses it): the message
            then says to start a new run.
    """

    def __init__(
        self, cause: BaseException, frames: int, run_dir: str | Path, resumable: bool = True
    ) -> None:
        self.cause = cause
        self.frames = frames
        self.run_dir = Path(run_dir)
        reason = str(cause) if isinstance(cause, ESLAMError) else _describe(cause)
        then = (
            f"fix the cause, then continue with `eslam resume {self.run_dir}`"
            if resumable
            else NOT_RESUMABLE
        )
        super().__init__(f"{reason}; {_saved(frames, self.run_dir)} ({then})")


NOT_RESUMABLE = "a real-time run cannot be resumed: start a new run"
"""What a stopped real-time run's message says instead of the resume command."""


def _saved(frames: int, run_dir: Path) -> str:
    """What a stopped run kept, for messages."""
    if frames == 0:
        return f"the run in {run_dir} stopped before its first frame was complete"
    return f"the run stopped after {frames} frames, saved in {run_dir}"


def _describe(error: BaseException) -> str:
    filename = getattr(error, "filename", None)
    mapped = output_error(error, filename) if filename else None
    if mapped is not None:
        return str(mapped)
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


class RunInterrupted(KeyboardInterrupt):
    """A run was interrupted (Ctrl-C, SIGTERM) after its completed frames were saved.

    Args:
        frames: frames completed and saved in the run folder; None when the run was
            interrupted while resuming, before it changed any saved frame.
        run_dir: the run folder.
        resumable: False for a real-time run (see :class:`RunStopped`).
    """

    def __init__(self, frames: int | None, run_dir: str | Path, resumable: bool = True) -> None:
        self.frames = frames
        self.run_dir = Path(run_dir)
        if frames is None:
            done = f"before resuming, its saved frames in {self.run_dir} unchanged"
        elif frames == 0:
            done = "before the first frame was complete"
        else:
            done = f"after {frames} frames, saved in {self.run_dir}"
        then = f"continue with `eslam resume {self.run_dir}`" if resumable else NOT_RESUMABLE
        super().__init__(f"interrupted {done} ({then})")
