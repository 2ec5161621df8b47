"""The run folder: standard paths, refusing to clobber a run, atomic stable JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from eslam.errors import InputError
from eslam.io.run_dir import (
    RunDirectory,
    default_run_name,
    prepare_run_directory,
    read_json,
    write_json,
)


def test_run_directory_paths(tmp_path: Path) -> None:
    run = RunDirectory(tmp_path / "r")
    names = {
        "config": "config.yaml",
        "trajectory": "trajectory.txt",
        "trajectory_gt": "trajectory_gt.txt",
        "map": "map.pt",
        "mesh": "mesh.ply",
        "mesh_culled": "mesh_culled.ply",
        "metrics": "metrics.json",
        "timings": "timings.json",
        "log": "log.txt",
    }
    for attribute, name in names.items():
        assert getattr(run, attribute) == tmp_path / "r" / name
    assert RunDirectory(str(tmp_path / "r")).root == tmp_path / "r"
    assert not (tmp_path / "r").exists()


def test_prepare_creates_a_new_folder(tmp_path: Path) -> None:
    run = prepare_run_directory(tmp_path / "runs" / "a", overwrite=False)
    assert run.root.is_dir() and run.root == tmp_path / "runs" / "a"
    (run.root / "notes.txt").write_text("a folder with other files is fine")
    assert prepare_run_directory(run.root).root == run.root


@pytest.mark.parametrize("marker", ["map.pt", "trajectory.txt", "metrics.json", "mesh.ply"])
def test_prepare_refuses_an_existing_run(tmp_path: Path, marker: str) -> None:
    (tmp_path / marker).write_text("earlier run")
    with pytest.raises(InputError) as caught:
        prepare_run_directory(tmp_path, overwrite=False)
    message = str(caught.value)
    assert "already holds a run" in message and marker in message
    assert "--overwrite" in message and "eslam resume" in message
    assert (tmp_path / marker).read_text() == "earlier run"


def test_a_run_that_saved_no_frame_is_started_again_without_overwrite(tmp_path: Path) -> None:
    # stopped before its first frame was complete: config.yaml and log.txt, nothing saved
    (tmp_path / "config.yaml").write_text("earlier run")
    (tmp_path / "log.txt").write_text("started")
    assert prepare_run_directory(tmp_path, overwrite=False).root == tmp_path
    assert RunDirectory(tmp_path).existing_markers() == []


def test_prepare_with_overwrite_deletes_nothing(tmp_path: Path) -> None:
    for name in ("config.yaml", "map.pt", "mesh.ply"):
        (tmp_path / name).write_text("earlier run")
    run = prepare_run_directory(tmp_path, overwrite=True)
    assert sorted(p.name for p in run.root.iterdir()) == ["config.yaml", "map.pt", "mesh.ply"]
    write_json(run.metrics, {"frames": 3})
    assert run.config.read_text() == "earlier run"


def test_prepare_refuses_a_file(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="is not a folder"):
        prepare_run_directory(tmp_path / "file", overwrite=True)


def test_default_run_name() -> None:
    assert default_run_name("configs/replica/room0.yaml", "20261123-101500") == (
        "runs/room0-20261123-101500"
    )
    assert default_run_name("demo", "20261123-101500") == "runs/demo-20261123-101500"
    assert default_run_name(None, "x").startswith("runs/demo-")
    name = default_run_name(Path("a/b.yaml"))
    assert name.startswith("runs/b-") and len(name) == len("runs/b-20261123-101500")


def test_write_json_is_stable_and_atomic(tmp_path: Path) -> None:
    path = tmp_path / "sub" / "metrics.json"
    metrics = {
        "frames": np.int64(3),
        "ate_rmse_cm": np.float32(1.5),
        "b": [1, (2, 3)],
        "a": {"z": np.arange(2), "y": float("nan"), "p": Path("x/y")},
    }
    write_json(path, metrics)
    text = path.read_text()
    assert text.endswith("}\n") and text.index('"a"') < text.index('"ate_rmse_cm"')
    assert read_json(path) == {
        "a": {"p": "x/y", "y": None, "z": [0, 1]},
        "ate_rmse_cm": 1.5,
        "b": [1, [2, 3]],
        "frames": 3,
    }
    write_json(path, dict(reversed(list(metrics.items()))))
    assert path.read_text() == text
    assert [p.name for p in path.parent.iterdir()] == ["metrics.json"]


def test_write_json_failure_keeps_the_old_file(tmp_path: Path) -> None:
    path = tmp_path / "metrics.json"
    write_json(path, {"frames": 1})
    with pytest.raises(TypeError):
        write_json(path, {"frames": object()})
    assert json.loads(path.read_text()) == {"frames": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.json"]


def test_read_json_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"missing\.json: not found"):
        read_json(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{oops")
    with pytest.raises(InputError, match=r"bad\.json: not valid JSON"):
        read_json(tmp_path / "bad.json")
