"""The live viewer of `eslam run` (``--viewer``, ``--viewer-save``): its observer, wired.

Called only when a viewer is asked for, so a run without one imports neither rerun nor
the viewer's modules.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

from eslam.config import ESLAMConfig
from eslam.slam.run.viewer import ViewerObserver
from eslam.viz.rerun_viewer import ViewerOutputs, open_rerun_sink

VIEWER_MODES = ("rerun", "rerun-web")
"""``--viewer`` choices: a rerun viewer spawned here, or served to a browser elsewhere."""


def viewer_observer(
    config: ESLAMConfig, run_dir: Path, mode: str | None, save: Path | None
) -> ViewerObserver:
    """The observer that shows the run in ``run_dir`` with viewer ``mode`` (one of
    :data:`VIEWER_MODES`, or None) and/or records it to ``save`` (.rrd).

    Raises:
        ConfigError: rerun is missing (the message names the extra) or cannot start.
    """
    if mode is not None and mode not in VIEWER_MODES:
        raise ValueError(f"unknown viewer '{mode}'; choose from {VIEWER_MODES}")
    outputs = ViewerOutputs(spawn=mode == "rerun", serve=mode == "rerun-web", save=save)
    return ViewerObserver(open_rerun_sink(Path(run_dir).name, outputs), config.viewer)


@contextlib.contextmanager
def viewer_observers(
    config: ESLAMConfig, run_dir: Path, mode: str | None, save: Path | None
) -> Iterator[list[ViewerObserver]]:
    """The observers to pass to ``run_slam`` while inside: the viewer's (see
    :func:`viewer_observer`), or none when neither ``mode`` nor ``save`` is given. On
    leaving, the viewer is closed however the run went (discarded if it never started)."""
    if mode is None and save is None:
        yield []
        return
    observer = viewer_observer(config, run_dir, mode, save)
    try:
        yield [observer]
    finally:
        observer.release()
