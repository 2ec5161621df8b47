"""The run folder: where each output of a run lives, and safe creation of a new one.

A run folder holds (README.md, "Quick start"): ``config.yaml`` (fully
resolved), ``trajectory.txt`` (TUM, camera-to-world), ``trajectory_gt.txt`` when ground
truth exists, ``map.pt`` (everything needed to resume), ``mesh.ply``,
``mesh_culled.ply``, ``metrics.json``, ``timings.json`` and ``log.txt``.

Every file is replaced atomically on its own (``eslam.atomic``); nothing here ever
deletes a file, so an interrupted run, or a re-run with ``--overwrite``, leaves each
file either old or new, never half written.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eslam.atomic import write_text
from eslam.errors import InputError
from eslam.io.run_lock import LOCK_NAME

RUN_MARKERS = ("map.pt", "trajectory.txt", "metrics.json", "mesh.ply")
"""Files whose presence means a folder holds a run's saved work (frames, results).

config.yaml alone is no such marker: a run stopped before its first frame was complete
saved nothing, and its folder may be started again (``eslam run``) or resumed from frame 0
(``eslam resume``) without ``--overwrite``.
"""


@dataclass(frozen=True)
class RunDirectory:
    """The standard file paths of a run folder (nothing is created by this class).

    Attributes:
        root: the run folder.
    """

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def config(self) -> Path:
        """config.yaml: the fully resolved configuration of the run."""
        return self.root / "config.yaml"

    @property
    def trajectory(self) -> Path:
        """trajectory.txt: estimated camera-to-world poses, TUM format."""
        return self.root / "trajectory.txt"

    @property
    def trajectory_gt(self) -> Path:
        """trajectory_gt.txt: ground-truth poses of the same frames, TUM format."""
        return self.root / "trajectory_gt.txt"

    @property
    def map(self) -> Path:
        """map.pt: the checkpoint (field, poses, keyframes; see eslam.io.checkpoint)."""
        return self.root / "map.pt"

    @property
    def mesh(self) -> Path:
        """mesh.ply: the mesh extracted from the field."""
        return self.root / "mesh.ply"

    @property
    def mesh_culled(self) -> Path:
        """mesh_culled.ply: the mesh without the parts no frame observed (for evaluation)."""
        return self.root / "mesh_culled.ply"

    @property
    def metrics(self) -> Path:
        """metrics.json: the run's metrics (keys in README.md)."""
        return self.root / "metrics.json"

    @property
    def timings(self) -> Path:
        """timings.json: seconds per frame spent tracking and mapping."""
        return self.root / "timings.json"

    @property
    def loops(self) -> Path:
        """loops.json: every loop candidate and its decision (with loop closure on)."""
        return self.root / "loops.json"

    @property
    def log(self) -> Path:
        """log.txt: the run's log."""
        return self.root / "log.txt"

    @property
    def input(self) -> Path:
        """input.json: where the input is and its fingerprint (resume checks it)."""
        return self.root / "input.json"

    @property
    def lock(self) -> Path:
        """run.lock: held by the run writing the folder (eslam.io.run_lock)."""
        return self.root / LOCK_NAME

    def existing_markers(self) -> list[str]:
        """Names of the files in :data:`RUN_MARKERS` present in the folder."""
        return [name for name in RUN_MARKERS if (self.root / name).exists()]


def check_run_folder(path: str | Path) -> RunDirectory:
    """The paths of run folder ``path``, checked to be a folder or absent (nothing is made).

    Raises:
        InputError: ``path`` is a file.
    """
    run = RunDirectory(Path(path))
    if run.root.exists() and not run.root.is_dir():
        raise InputError(run.root, "exists and is not a folder", "choose another --out")
    return run


def check_new_run(run: RunDirectory, overwrite: bool = False) -> None:
    """Refuse to start a new run in a folder that holds saved work, unless ``overwrite``.

    A folder with only config.yaml (and log.txt) holds a run that stopped before its
    first frame was complete: it saved nothing, so it is started again freely.

    Raises:
        InputError: the folder holds saved work and ``overwrite`` is False (the message
            offers ``--overwrite`` and ``eslam resume``).
    """
    markers = run.existing_markers()
    if markers and not overwrite:
        raise InputError(
            run.root,
            f"already holds a run ({', '.join(markers)})",
            "choose another --out, pass --overwrite, or continue it with "
            f"`eslam resume {run.root}`",
        )


def prepare_run_directory(path: str | Path, overwrite: bool = False) -> RunDirectory:
    """Create (if needed) the folder of a new run and return its paths.

    A folder that already holds a run's saved work (:data:`RUN_MARKERS`) is refused
    unless ``overwrite``. Even then nothing is deleted: each output of the new run
    replaces the old file atomically when it is written, so stopping early leaves a
    mix of old and new files rather than a half-empty folder.

    Raises:
        InputError: ``path`` is a file, or holds a run and ``overwrite`` is False.
    """
    run = check_run_folder(path)
    check_new_run(run, overwrite)
    run.root.mkdir(parents=True, exist_ok=True)
    return run


def default_run_name(
    config: str | Path | None = None, stamp: str | None = None, parent: str = "runs"
) -> str:
    """Default folder of a run: ``runs/<config name>-<YYYYmmdd-HHMMSS>``.

    Args:
        config: the config file (its stem names the run), or None for "demo".
        stamp: the time stamp to use; default the local time now (pass one in tests).
        parent: the folder holding runs.

    Example:
        ``default_run_name("configs/replica/room0.yaml", "20261123-101500")`` is
        ``"runs/room0-20261123-101500"``.
    """
    name = "demo" if config is None else Path(config).stem or "run"
    if stamp is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
    return f"{parent}/{name}-{stamp}"


def _plain(value: object) -> object:
    """JSON-ready copy: numpy values as Python ones, paths as text, nan/inf as null."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: str | Path, obj: object) -> None:
    """Write ``obj`` as JSON atomically: sorted keys, 2-space indent, trailing newline.

    numpy scalars and arrays become numbers and lists, paths become text, and
    non-finite floats become ``null`` (strict JSON has no nan or inf).

    Raises:
        TypeError: a value JSON cannot hold (the error names its type).
    """
    write_text(path, json_text(obj) + "\n")


def json_text(obj: object) -> str:
    """``obj`` as JSON text the way :func:`write_json` writes it (no trailing newline)."""
    return json.dumps(_plain(obj), indent=2, sort_keys=True, allow_nan=False)


def read_json(path: str | Path) -> object:
    """Read a JSON file.

    Raises:
        InputError: the file is missing or is not valid JSON.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "not found")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise InputError(path, f"not valid JSON ({error})") from None
