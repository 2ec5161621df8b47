"""User-facing errors: one line that names what is wrong and how to fix it.

The CLI prints ``str(error)`` of any :class:`ESLAMError` on one line and exits with
status 2, so every message must be complete without a traceback.
"""

from __future__ import annotations

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


class ConfigError(ESLAMError):
    """A configuration file or a command-line override is invalid."""


class RunStopped(ESLAMError):
    """A run stopped on an error after some frames were saved: it can be resumed.

    The message is the cause's, followed by what was saved and how to continue.

    Args:
        cause: the error that stopped the run (an ESLAMError's message is kept as is).
        frames: frames completed and saved in the run folder.
        run_dir: the run folder.
    """

    def __init__(self, cause: BaseException, frames: int, run_dir: str | Path) -> None:
        self.cause = cause
        self.frames = frames
        self.run_dir = Path(run_dir)
        reason = str(cause) if isinstance(cause, ESLAMError) else _describe(cause)
        super().__init__(
            f"{reason}; {_saved(frames, self.run_dir)} "
            f"(fix the cause, then continue with `eslam resume {self.run_dir}`)"
        )


def _saved(frames: int, run_dir: Path) -> str:
    """What a stopped run kept, for messages."""
    if frames == 0:
        return f"the run in {run_dir} stopped before its first frame was complete"
    return f"the run stopped after {frames} frames, saved in {run_dir}"


def _describe(error: BaseException) -> str:
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


class RunInterrupted(KeyboardInterrupt):
    """A run was interrupted (Ctrl-C, SIGTERM) after its completed frames were saved.

    Args:
        frames: frames completed and saved in the run folder; None when the run was
            interrupted while resuming, before it changed any saved frame.
        run_dir: the run folder.
    """

    def __init__(self, frames: int | None, run_dir: str | Path) -> None:
        self.frames = frames
        self.run_dir = Path(run_dir)
        if frames is None:
            done = f"before resuming, its saved frames in {self.run_dir} unchanged"
        elif frames == 0:
            done = "before the first frame was complete"
        else:
            done = f"after {frames} frames, saved in {self.run_dir}"
        super().__init__(f"interrupted {done} (continue with `eslam resume {self.run_dir}`)")
