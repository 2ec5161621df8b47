"""File formats: pose and trajectory text, meshes, run folders, checkpoints.

Every write is atomic (``eslam.atomic``): a reader never sees a half-written file.
"""

from eslam.io.checkpoint import CHECKPOINT_VERSION, load_checkpoint, save_checkpoint
from eslam.io.run_dir import (
    RunDirectory,
    default_run_name,
    prepare_run_directory,
    read_json,
    write_json,
)
from eslam.io.saved_run import SavedRun, load_run
from eslam.io.trajectory import read_trajectory, read_tum_trajectory, write_tum_trajectory

__all__ = [
    "CHECKPOINT_VERSION",
    "RunDirectory",
    "SavedRun",
    "default_run_name",
    "load_checkpoint",
    "load_run",
    "prepare_run_directory",
    "read_json",
    "read_trajectory",
    "read_tum_trajectory",
    "save_checkpoint",
    "write_json",
    "write_tum_trajectory",
]
