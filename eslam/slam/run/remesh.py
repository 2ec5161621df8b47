"""`eslam mesh`: extract mesh.ply again from a run folder's saved map."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

from eslam.config import load_config
from eslam.config.device import resolve_device
from eslam.errors import ConfigError, InputError
from eslam.io.mesh_files import write_mesh_ply
from eslam.io.run_dir import RunDirectory
from eslam.mesh.extract import extract_mesh
from eslam.slam.state import load_state
from eslam.types import TriangleMesh

log = logging.getLogger("eslam")


@dataclass(frozen=True)
class RemeshResult:
    """What :func:`remesh_run` wrote.

    Attributes:
        path: the mesh file (RUN_DIR/mesh.ply).
        vertices, faces: its size.
        resolution: the grid step used, metres.
        seconds: wall time of the extraction (loading and writing excluded).
    """

    path: Path
    vertices: int
    faces: int
    resolution: float
    seconds: float


def remesh_run(
    run_dir: str | Path, resolution: float | None = None, device: str = "cpu"
) -> RemeshResult:
    """Re-extract RUN_DIR/mesh.ply from RUN_DIR/map.pt and config.yaml (atomically).

    Args:
        run_dir: a run folder written by ``eslam run``.
        resolution: grid step, metres; None = the run's ``output.mesh_resolution``.
        device: where the field is evaluated (cpu, cuda, cuda:N).

    Raises:
        InputError: the folder has no config.yaml or map.pt, or they do not match.
        ConfigError: bad resolution or device.
    """
    run = RunDirectory(Path(run_dir))
    for path in (run.config, run.map):
        if not path.is_file():
            raise InputError(path, "not found", "give the folder of a run made by `eslam run`")
    if resolution is not None and not resolution > 0:
        raise ConfigError(f"--resolution must be > 0 metres, got {resolution}")
    config = load_config(run.config)
    step = config.output.mesh_resolution if resolution is None else float(resolution)
    target = resolve_device(device)
    state = load_state(run.map, config, target)
    if len(state.keyframes) == 0:
        raise InputError(run.map, "holds no keyframes, so no space was observed", "run longer")
    start = time.perf_counter()
    mesh: TriangleMesh = extract_mesh(state.field, step, state.observed_views())
    seconds = time.perf_counter() - start
    write_mesh_ply(run.mesh, mesh)
    log.info(
        "remeshed %s at %.3f m: %d vertices in %.1f s", run.root, step, len(mesh.vertices), seconds
    )
    return RemeshResult(
        path=run.mesh,
        vertices=len(mesh.vertices),
        faces=len(mesh.faces),
        resolution=step,
        seconds=seconds,
    )
