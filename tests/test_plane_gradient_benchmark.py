"""benchmarks/plane_gradient.py: both plane gradients timed in one table, bad input
refused with a usage error."""

from __future__ import annotations

from pathlib import Path

import pytest

from eslam.testing.scripts import load_script

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture
def script(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))  # it imports _machine and bench_core
    return load_script(BENCHMARKS / "plane_gradient.py")


def test_times_the_sorted_and_the_scattered_gradient_side_by_side(script, capsys):
    unit = "[[0, 1], [0, 1], [0, 1]]"
    script.main(["--repeats", "1", "--warmup", "0", "--no-append", "--bound", unit])
    out = capsys.readouterr().out
    assert "Plane gradient: sorted sum against scattered adds" in out
    rows = [line for line in out.splitlines() if line.startswith("| mapping iteration")]
    rows += [line for line in out.splitlines() if line.startswith("| field query")]
    assert len(rows) == 2
    for row in rows:
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        assert all(float(cell) > 0 for cell in cells[1:])


@pytest.mark.parametrize("bound", ["[[0, 1], [0, 1]]", "not json"])
def test_a_bad_bound_is_a_usage_error(script, bound, capsys):
    with pytest.raises(SystemExit) as stop:
        script.main(["--bound", bound, "--no-append"])
    assert stop.value.code == 2 and "--bound" in capsys.readouterr().err
