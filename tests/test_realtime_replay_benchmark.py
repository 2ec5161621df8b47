"""benchmarks/realtime_replay.py: a recording replayed in real time per mapping mode."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eslam.synthetic import read_synthetic_bound
from eslam.testing.scripts import load_script
from tests.conftest import TINY

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "realtime_replay.py"


def test_a_missing_metric_is_a_dash_and_pairs_share_a_cell() -> None:
    script = load_script(SCRIPT)
    metrics = {"frames": 7, "tracking_lag_s_mean": 0.4, "tracking_lag_s_max": 1.5}
    text = script.table({"in-turn": metrics})
    head, rule, row = text.splitlines()
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert head.count("|") == rule.count("|") == row.count("|")
    assert cells[0] == "in-turn" and cells[1] == "7"
    assert cells[2] == "-"  # no frames_dropped: not a real-time run's metrics
    assert "0.4 / 1.5" in cells  # mean / largest lag


@pytest.mark.slow  # one tiny real-time run in a fresh process
def test_a_mode_is_run_in_real_time_and_reported_from_its_metrics(
    tiny_sequence: Path, tmp_path: Path, capsys
) -> None:
    script = load_script(SCRIPT)
    bound = read_synthetic_bound(tiny_sequence)
    settings = [
        "--config", "demo", "--data", str(tiny_sequence), "--out", str(tmp_path),
        "--mode", "beside", *TINY, f"scene.bound={bound}", "data.replay_fps=100",
        "mapping.first_iterations=5", "output.mesh=false",
    ]  # fmt: skip
    assert script.main(settings) == 0
    rows = capsys.readouterr().out.strip().splitlines()
    metrics = json.loads((tmp_path / "beside" / "metrics.json").read_text())
    assert metrics["mapping_concurrent"] is True
    cells = [cell.strip() for cell in rows[2].strip("|").split("|")]
    assert cells[:3] == ["beside", str(metrics["frames"]), str(metrics["frames_dropped"])]
