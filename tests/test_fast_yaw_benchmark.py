"""benchmarks/fast_yaw.py: the synthetic room at several yaw rates, one table row each."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eslam.testing.scripts import load_script
from tests.conftest import TINY

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "fast_yaw.py"

pytestmark = pytest.mark.slow  # two tiny runs


def test_each_rate_is_run_and_reported_from_its_metrics(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    settings = [*TINY, "tracking.method=sdf", "output.checkpoint_every=100"]
    arguments = ["--steps", "0.5", "2", "--frames", "6", "--size", "64x48"]
    script.main([*arguments, "--out", str(tmp_path), *settings])
    rows = capsys.readouterr().out.strip().splitlines()
    assert rows[0].startswith("| yaw (deg/frame) | deg/s at 30 fps |") and len(rows) == 4
    for row, step in zip(rows[2:], ("0.5", "2"), strict=True):
        metrics = json.loads((tmp_path / f"run-{step}" / "metrics.json").read_text())
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        assert cells[0] == step and float(cells[1]) == 30 * float(step)
        assert cells[2] == str(metrics["tracking_failures"])
        assert cells[4] == str(metrics["tracking_ended_tracked"])
        assert float(cells[5]) == pytest.approx(metrics["ate_rmse_cm"], abs=1e-3)
    # the faster camera turned more between frames: its sequence is another one
    assert (tmp_path / "data-2" / "traj.txt").read_text() != (
        tmp_path / "data-0.5" / "traj.txt"
    ).read_text()


def test_bad_arguments_are_one_line(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    with pytest.raises(SystemExit) as stop:
        script.main(["--steps", "0", "--out", str(tmp_path)])
    assert stop.value.code == 2
    assert "--steps must be positive" in capsys.readouterr().err
