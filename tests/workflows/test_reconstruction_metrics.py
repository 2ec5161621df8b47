"""`eslam recon`'s computation as a function: mesh_errors on two small spheres."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

import eslam.workflows.reconstruction_metrics as reconstruction_metrics
from eslam.errors import ConfigError, InputError
from eslam.io.mesh_files import write_mesh_ply
from eslam.types import TriangleMesh
from eslam.workflows.reconstruction_metrics import mesh_errors

SAMPLES = 3000
"""Few samples: the spheres are smooth, and the test stays short."""


def _sphere(path: Path, radius: float) -> Path:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    vertices = np.asarray(sphere.vertices)
    colours = np.zeros(vertices.shape, np.uint8)
    write_mesh_ply(path, TriangleMesh(vertices, np.asarray(sphere.faces), colours))
    return path


def test_a_mesh_against_itself_and_one_centimetre_larger(tmp_path: Path) -> None:
    gt = _sphere(tmp_path / "gt.ply", 1.0)
    rec = _sphere(tmp_path / "run" / "mesh.ply", 1.0)
    itself = mesh_errors(tmp_path / "run", gt, samples=SAMPLES, exact=True)
    assert itself.rec == rec and itself.gt == gt and itself.depth_l1 is None
    metrics = itself.as_dict()
    assert metrics["accuracy_cm"] < 1e-9 and metrics["completion_ratio_pct"] == 100.0
    assert metrics["samples"] == SAMPLES and metrics["exact"] is True
    assert "depth_l1_cm" not in metrics
    larger = mesh_errors(_sphere(tmp_path / "larger.ply", 1.01), gt, samples=SAMPLES, exact=True)
    assert larger.reconstruction.accuracy_cm == pytest.approx(1.0, abs=0.05)


def test_depth_l1_is_added_last(tmp_path: Path) -> None:
    gt = _sphere(tmp_path / "gt.ply", 1.0)
    result = mesh_errors(gt, gt, samples=SAMPLES, depth_l1=True, views=2)
    assert result.depth_l1 is not None and result.depth_l1.views_used == 2
    assert list(result.as_dict())[-3:] == ["depth_l1_cm", "views_used", "views_rejected"]
    assert result.as_dict()["depth_l1_cm"] == 0.0


def test_errors_name_the_mesh(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    gt = _sphere(tmp_path / "gt.ply", 1.0)
    (tmp_path / "empty_run").mkdir()
    with pytest.raises(InputError, match=r"nothing\.ply: not found"):
        mesh_errors(tmp_path / "nothing.ply", gt)
    with pytest.raises(InputError, match=r"empty_run: holds no mesh_culled\.ply or mesh\.ply"):
        mesh_errors(tmp_path / "empty_run", gt)

    def no_ray_caster(*args: object) -> None:
        raise ImportError("the depth L1 needs embreex")

    monkeypatch.setattr(reconstruction_metrics, "measure_depth_l1", no_ray_caster)
    with pytest.raises(ConfigError, match="--depth-l1: the depth L1 needs embreex"):
        mesh_errors(gt, gt, samples=SAMPLES, depth_l1=True, views=2)
