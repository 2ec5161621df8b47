"""Synthetic sequences on disk: the Replica layout plus mesh.ply and synth.json.

The output folder reads back with :class:`~eslam.data.replica.ReplicaSequence` and also
holds the ground-truth ``mesh.ply`` in the same world frame (metres, z up, floor at
z = 0) and ``synth.json`` with the configuration used and the scene bound.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from eslam.atomic import atomic_directory, write_text
from eslam.data.replica import REPLICA_DEPTH_SCALE, write_replica_sequence
from eslam.errors import InputError
from eslam.io.mesh_files import write_mesh_ply
from eslam.synthetic.config import FPS, SynthConfig
from eslam.synthetic.mesh import scene_mesh
from eslam.synthetic.scenes import build_scene, describe_scene, scene_bound
from eslam.synthetic.sequence import generate_sequence


def read_synthetic_bound(root: str | Path) -> list[list[float]]:
    """The scene bound recorded in ``root/synth.json`` by :func:`write_synthetic_sequence`."""
    path = Path(root) / "synth.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))["bound"]
    except FileNotFoundError:
        raise InputError(path, "not found (is this a folder written by `eslam synth`?)") from None
    except (KeyError, json.JSONDecodeError) as error:
        raise InputError(
            path, f"has no scene bound ({error})", "rewrite it with `eslam synth`"
        ) from None


def write_synthetic_sequence(
    out_dir: str | Path, config: SynthConfig, overwrite: bool = False
) -> Path:
    """Write the sequence of ``config`` to ``out_dir`` in the Replica layout.

    ``out_dir`` gets ``results/frame*.jpg``, ``results/depth*.png``, ``traj.txt``,
    ``cam_params.json``, the ground-truth ``mesh.ply`` and ``synth.json``. The folder
    is built beside ``out_dir`` and moved into place when complete.

    Raises:
        InputError: ``out_dir`` exists and is not empty (and ``overwrite`` is off).
    """
    out_dir = Path(out_dir)
    scene = build_scene(config.scene, config.seed)
    try:
        with atomic_directory(out_dir, overwrite=overwrite) as staging:
            write_mesh_ply(staging / "mesh.ply", scene_mesh(scene))
            write_replica_sequence(staging, generate_sequence(config), REPLICA_DEPTH_SCALE)
            info = {
                "config": asdict(config),
                "fps": FPS,
                "world": "metres, z up, floor at z = 0; poses camera-to-world, OpenCV axes",
                "mesh": "mesh.ply",
                "scene": describe_scene(scene),
                "bound": scene_bound(scene),
            }
            write_text(staging / "synth.json", json.dumps(info, indent=2) + "\n")
    except FileExistsError as error:
        raise InputError(
            out_dir, "already exists and is not empty", "choose a new folder"
        ) from error
    return out_dir
