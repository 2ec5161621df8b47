"""What a stopped run raises: every stop a user can cause names ``eslam resume RUN``.

The run loop rolls a failed frame back and the run writer saves the completed frames
(:mod:`eslam.slam.run.writer`); this module turns the error into the one line the CLI
prints (:class:`~eslam.errors.RunStopped`, exit 2, or
:class:`~eslam.errors.RunInterrupted`, exit 130), so the user learns what was saved and
the exact command that continues the run.
"""

from __future__ import annotations

import logging
from pathlib import Path

import torch

from eslam.errors import ESLAMError, RunInterrupted, RunStopped
from eslam.io.run_dir import RunDirectory
from eslam.slam.run.observers import Observers


def save_on_failure(
    observers: Observers, error: BaseException, frames: int, logger: logging.Logger
) -> None:
    """Tell the observers (the run writer saves the completed frames); a failure to save
    is logged, never raised over ``error``, which is what the user must see."""
    try:
        observers.on_failure(error, frames)
    except Exception as nested:
        logger.error("could not save the completed frames: %s: %s", type(nested).__name__, nested)


def stopped_error(
    error: BaseException, frames: int, run_dir: Path, resumable: bool = True
) -> BaseException:
    """What to raise for ``error`` once ``frames`` frames are saved in ``run_dir``
    (``resumable`` False: a real-time run, whose message says to start a new run).

    Every stop a user can cause (Ctrl-C, SIGTERM, bad input, a full disk, out of memory)
    becomes an error naming ``eslam resume RUN``, even before the first frame was
    complete (resume then starts at frame 0). Anything else is a bug: it propagates
    with a note saying where the completed frames are.
    """
    if isinstance(error, RunStopped | RunInterrupted):
        return error
    if isinstance(error, KeyboardInterrupt):
        return RunInterrupted(frames, run_dir, resumable)
    user_caused = isinstance(
        error, ESLAMError | OSError | MemoryError | torch.cuda.OutOfMemoryError
    )
    if user_caused:
        return RunStopped(error, frames, run_dir, resumable)
    then = f"continue with `eslam resume {run_dir}`" if resumable else "a real-time run"
    error.add_note(f"eslam: {frames} completed frames are saved in {run_dir} ({then})")
    return error


def interrupted_early(
    interrupt: KeyboardInterrupt, run_dir: Path, resume: bool
) -> KeyboardInterrupt:
    """What to raise for Ctrl-C / SIGTERM while a run folder is being opened, before the
    run's state exists: nothing was processed, so a new run is resumed from frame 0 and a
    resumed one from where it was, once config.yaml is there (else no run folder exists
    yet and the interruption is raised as it is)."""
    if not RunDirectory(run_dir).config.is_file():
        return interrupt
    return RunInterrupted(None if resume else 0, run_dir)
