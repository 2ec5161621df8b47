"""benchmarks/reversal.py: a reversing camera on the synthetic room, one row per start."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from eslam.testing.scripts import load_script
from tests.conftest import TINY

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "reversal.py"


@pytest.mark.slow  # two tiny runs
def test_each_start_is_run_and_reported_from_its_metrics(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    arguments = ["--forward", "5", "--size", "64x48", "--out", str(tmp_path)]
    script.main([*arguments, *TINY, "tracking.method=sdf"])
    rows = capsys.readouterr().out.strip().splitlines()
    assert rows[0].startswith("| start | failed frames |") and len(rows) == 4
    data = np.loadtxt(tmp_path / "data" / "traj.txt").reshape(-1, 4, 4)
    assert len(data) == 5 + 2  # 0-4, then 2 and 0
    np.testing.assert_array_equal(data[5], data[2])
    for row, name in zip(rows[2:], ("motion", "features"), strict=True):
        run_dir = tmp_path / f"run-{rows.index(row) - 2}"
        metrics = json.loads((run_dir / "metrics.json").read_text())
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        assert cells[0] == name and cells[1] == str(metrics["tracking_failures"])
        assert float(cells[2].removesuffix(" cm")) == pytest.approx(
            metrics["ate_rmse_cm"], abs=1e-2
        )
        assert ("tracking_starts" in metrics) == (name == "features")


def test_bad_arguments_are_one_line(tmp_path: Path, capsys) -> None:
    script = load_script(SCRIPT)
    with pytest.raises(SystemExit) as stop:
        script.main(["--forward", "2", "--out", str(tmp_path)])
    assert stop.value.code == 2
    assert "--forward must be >= 4" in capsys.readouterr().err
