"""benchmarks/tracking_quality.py: a run's per-frame quality summarised by frame ranges."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eslam.testing.scripts import load_script

tracking_quality = load_script(
    Path(__file__).resolve().parents[1] / "benchmarks" / "tracking_quality.py"
)


def write_run(folder: Path) -> Path:
    """Six frames: frame 0 not judged, 1-2 well constrained, 3-5 degenerate."""
    folder.mkdir()
    timings = {
        "tracking_s": [9.0, 0.1, 0.3, 0.2, 0.4, 0.6],
        "tracking_information": [None, 0.12, 0.10, 0.002, 0.001, 0.003],
        "tracking_degenerate_directions": [None, 0.0, 0.0, 2.0, 3.0, 1.0],
    }
    (folder / "timings.json").write_text(json.dumps(timings))
    return folder


def test_ranges_summarise_their_own_frames(tmp_path: Path) -> None:
    timings = json.loads((write_run(tmp_path / "run") / "timings.json").read_text())
    good = tracking_quality.range_quality(timings, 1, 3)
    assert (good.information_min, good.information_max) == (0.10, 0.12)
    assert good.degenerate_frames == 0 and good.tracking_s_median == pytest.approx(0.2)
    bad = tracking_quality.range_quality(timings, 3, 6)
    assert bad.information_median == 0.002 and bad.degenerate_frames == 3
    assert bad.tracking_s_median == 0.4
    whole = tracking_quality.range_quality(timings, 0, 6)  # frame 0's null left out
    assert whole.information_min == 0.001 and whole.degenerate_frames == 3


def test_command_prints_one_row_per_range(tmp_path: Path, capsys) -> None:
    run = write_run(tmp_path / "run")
    tracking_quality.main([str(run), "--bounds", "1", "3", "6"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert rows[1:] == [
        "| 1-2 | 0.1 | 0.11 | 0.12 | 0 | 0.200 |",
        "| 3-5 | 0.001 | 0.002 | 0.003 | 3 | 0.400 |",
    ]
    tracking_quality.main([str(run), "--every", "4"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert [row.split(" | ")[0] for row in rows[1:]] == ["| 0-3", "| 4-5"]


def test_a_run_without_quality_is_refused(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "timings.json").write_text(json.dumps({"tracking_s": [0.1]}))
    with pytest.raises(SystemExit, match="no per-frame tracking quality"):
        tracking_quality.main([str(run), "--every", "5"])
