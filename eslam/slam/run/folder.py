"""Opening a run folder for writing: the lock, config.yaml and the input's fingerprint.

Before a run writes a frame, its folder must be its own and must describe the run:

- the single-writer lock (:mod:`eslam.io.run_lock`) is taken first, so a second
  ``eslam run --overwrite`` or ``eslam resume`` into a folder whose run is alive is
  refused before it changes anything; it is released however the run ends;
- a new run checks the folder holds no saved work (unless ``--overwrite``) and writes
  config.yaml with ``data.path`` absolute, so ``eslam resume`` and ``eslam eval`` find
  the data from any working directory, and input.json (the data's location and
  fingerprint, :mod:`eslam.data.fingerprint`);
- a resumed run checks the sequence against input.json (a sequence that grew, shrank
  or changed is refused with one line, before anything is written) and then records
  where the data is now (``eslam resume RUN --data PATH`` for data that moved).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
from collections.abc import Iterator
from pathlib import Path

from eslam.config import ESLAMConfig, save_config
from eslam.data import RGBDSequence
from eslam.data.fingerprint import InputFingerprint, differences, fingerprint
from eslam.errors import InputError
from eslam.io.run_dir import RunDirectory, check_new_run, check_run_folder, read_json, write_json
from eslam.io.run_lock import HeldLock, run_folder_lock


def absolute_data_path(config: ESLAMConfig) -> ESLAMConfig:
    """``config`` with ``data.path`` made absolute against the current directory.

    A run folder outlives the shell it was started from: a relative path in its
    config.yaml would point somewhere else from any other directory. Symbolic links are
    kept as the user named them (``os.path.abspath``, not ``resolve``).
    """
    path = config.data.path
    if path is None:
        return config
    absolute = os.path.abspath(os.path.expanduser(str(path)))
    if absolute == path:
        return config
    return dataclasses.replace(config, data=dataclasses.replace(config.data, path=absolute))


@contextlib.contextmanager
def open_run_folder(
    run_dir: str | Path,
    config: ESLAMConfig,
    sequence: RGBDSequence | None,
    resume: bool,
    overwrite: bool = False,
) -> Iterator[tuple[RunDirectory, HeldLock]]:
    """Hold ``run_dir`` for a run inside the block (module doc); yield its paths and lock.

    Args:
        run_dir: the run folder (created for a new run).
        config: the run's configuration (``data.path`` already absolute).
        sequence: the recorded input, or None for a live source (no fingerprint).
        resume: continue the run in the folder instead of starting one.
        overwrite: start a new run in a folder that holds saved work.

    Raises:
        InputError: not a run folder (resume), saved work without ``overwrite``, a live
            run holds the folder, or the sequence is not the one the run started on.
    """
    run = check_run_folder(run_dir)
    if resume:
        _check_resumable(run)
    else:
        run.root.mkdir(parents=True, exist_ok=True)
    command = "eslam resume" if resume else "eslam run"
    with run_folder_lock(run.root, command) as lock:
        if resume:
            check_same_input(run, sequence)
        else:
            check_new_run(run, overwrite)
        save_config(config, run.config)
        if sequence is not None:
            write_json(run.input, {"path": str(sequence.root), **fingerprint(sequence).to_dict()})
        yield run, lock


def _check_resumable(run: RunDirectory) -> None:
    if not run.root.is_dir():
        raise InputError(run.root, "not found", "pass the folder of a run started with `eslam run`")
    if not run.config.is_file():
        raise InputError(
            run.config,
            "not found: not a run folder",
            f"start a run there with `eslam run CONFIG --out {run.root}`",
        )


def check_same_input(run: RunDirectory, sequence: RGBDSequence | None) -> None:
    """Refuse a sequence whose fingerprint differs from the one input.json recorded."""
    if sequence is None or not run.input.is_file():
        return  # a live source, or a folder written before fingerprints: nothing to check
    recorded = read_json(run.input)
    try:
        before = InputFingerprint.from_dict(recorded if isinstance(recorded, dict) else {})
    except ValueError as error:
        raise InputError(run.input, str(error), "restore it, or start a new run") from None
    found = differences(before, fingerprint(sequence))
    if found:
        was = recorded.get("path") if isinstance(recorded, dict) else None
        where = f" (it was {was})" if was and str(was) != str(sequence.root) else ""
        raise InputError(
            sequence.root,
            f"is not the input the run in {run.root} started on{where}: {'; '.join(found)}",
            f"pass the original sequence with `eslam resume {run.root} --data PATH`, "
            "or start a new run with `eslam run`",
        )


def log_lock_takeover(lock: HeldLock, logger: logging.Logger) -> None:
    """Say in the run's log that a stale lock (its run is gone) was taken over."""
    if lock.replaced is not None:
        logger.warning(
            "took over the lock %s of a run that is no longer running (%s)",
            lock.path,
            lock.replaced.describe(),
        )


def check_saved_frames(sequence: RGBDSequence | None, saved: int, checkpoint: Path) -> None:
    """Refuse a sequence shorter than the frames already saved (a run folder without
    input.json has no fingerprint to catch it earlier)."""
    if sequence is not None and len(sequence) < saved:
        raise InputError(
            sequence.root,
            f"holds {len(sequence)} frames but {checkpoint} already has {saved}",
            f"pass the original sequence with `eslam resume {checkpoint.parent} --data PATH`",
        )
