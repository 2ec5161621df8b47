"""Atomic file writes: a reader never sees a half-written file.

Everything eslam writes goes through here: the content is written to a temporary
file in the destination folder and moved into place with ``os.replace``, which is
atomic on POSIX and Windows. A crash mid-write leaves the old file (or none).

A write that fails for a reason the user can fix (disk full, read-only file system,
no permission, a path under /proc or /sys) raises :class:`~eslam.errors.OutputError`:
one line naming the file and the fix, which the CLI prints with exit status 2.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from eslam.errors import output_error, refuse_virtual_location


def _umask() -> int:
    current = os.umask(0)
    os.umask(current)
    return current


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; move it onto ``path`` on success.

    On an exception the temporary file is removed and ``path`` is left untouched.
    The temporary name keeps the suffix of ``path`` so writers that infer the format
    from the extension (Pillow, trimesh) work unchanged.
    """
    path = Path(path)
    refuse_virtual_location(path)
    with _as_output_error(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent
        )
        os.close(fd)
    tmp = Path(tmp_name)
    try:
        with _as_output_error(path):
            # mkstemp makes the file private (0600); give it the permissions open() would.
            os.chmod(tmp, 0o666 & ~_umask())
            yield tmp
            os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def _as_output_error(path: Path) -> Iterator[None]:
    """Turn a write failure the user can fix into OutputError naming ``path``; let any
    other error (a bug, the writer's own checks) through unchanged."""
    try:
        yield
    except (OSError, RuntimeError) as error:
        mapped = output_error(error, path)
        if mapped is None:
            raise
        raise mapped from error


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_with(path: str | Path, writer: Callable[[Path], None]) -> None:
    """Call ``writer(tmp_path)`` and move the result onto ``path`` atomically."""
    with atomic_path(path) as tmp:
        writer(tmp)


@contextlib.contextmanager
def atomic_directory(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Build a folder under a temporary name and publish it at ``path`` only on success.

    An interrupted or failed build leaves ``path`` as it was (absent, or the earlier
    folder). With ``overwrite`` an existing ``path`` is replaced once the new one is
    complete; without it an existing non-empty ``path`` raises FileExistsError before
    anything is written.

    Yields:
        The temporary folder to write into (beside ``path``, same file system).
    """
    path = Path(path)
    refuse_virtual_location(path)
    if path.exists() and not path.is_dir():
        raise FileExistsError(f"{path} exists and is not a folder")
    if path.is_dir() and any(path.iterdir()) and not overwrite:
        raise FileExistsError(f"{path} already exists and is not empty")
    with _as_output_error(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.partial-", dir=path.parent))
    try:
        with _as_output_error(path):
            os.chmod(staging, 0o777 & ~_umask())
            yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    with _as_output_error(path):
        old = None
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-", dir=path.parent))
            os.replace(path, old / path.name)
        os.replace(staging, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
