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
