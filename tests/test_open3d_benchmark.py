"""benchmarks/open3d_slam.py: Open3D's dense RGB-D SLAM as a peer on the frames eslam
reads. Without Open3D it says how to install it; with it (the ``bench`` extra) it tracks
the first frames of TUM fr1/xyz against motion-capture ground truth."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "open3d_slam.py"


def test_without_open3d_it_names_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    script = load_script(SCRIPT)
    monkeypatch.setitem(sys.modules, "open3d", None)  # import open3d raises ImportError
    with pytest.raises(SystemExit) as stop:
        script.main(["--data", str(tmp_path), "--out", str(tmp_path / "out")])
    assert stop.value.code == 2
    assert "pip install 'eslam[bench]'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_open3d_tracks_the_first_frames_of_fr1_xyz(real_data: Path, tmp_path: Path) -> None:
    pytest.importorskip("open3d", reason="the bench extra (Open3D) is not installed")
    script = load_script(SCRIPT)
    data = real_data / "tum-fr1-xyz"
    config = str(Path(__file__).resolve().parents[1] / "configs" / "tum" / "tum_cpu.yaml")
    script.main(["--config", config, "--data", str(data), "--out", str(tmp_path), "--frames", "30"])
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    estimate = np.loadtxt(tmp_path / "trajectory.txt")
    assert metrics["frames"] == 30 and len(estimate) == 30
    assert metrics["ate_rmse_cm"] < 3.0
    moved = np.linalg.norm(estimate[-1, 1:4] - estimate[0, 1:4])
    assert moved > 0.05  # fr1/xyz moves ~10 cm in its first second: not a held pose


def test_overrides_change_how_the_frames_are_read(real_data: Path, tmp_path: Path, capsys) -> None:
    pytest.importorskip("open3d", reason="the bench extra (Open3D) is not installed")
    script = load_script(SCRIPT)
    data = real_data / "tum-fr1-xyz"
    with pytest.raises(SystemExit) as stop:
        script.main(["--data", str(data), "--out", str(tmp_path / "out"), "data.pairing=any"])
    assert stop.value.code == 2
    assert "pairing" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
