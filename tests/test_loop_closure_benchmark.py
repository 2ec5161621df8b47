"""benchmarks/loop_closure.py's per-run figures: position errors without alignment (frame
0 at its ground truth), the error back at the start and the profile line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.io.trajectory import RUN_TRAJECTORY, RUN_TRAJECTORY_GT, write_tum_trajectory
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "loop_closure.py"


def test_errors_are_read_without_alignment(tmp_path: Path) -> None:
    script = load_script(SCRIPT)
    truth = np.tile(np.eye(4), (30, 1, 1))
    truth[:, 0, 3] = np.linspace(0.0, 0.29, 30)
    estimate = truth.copy()
    estimate[:, 1, 3] = 0.001 * np.arange(30)  # drifts 1 mm a frame sideways
    times = np.arange(30, dtype=float)
    write_tum_trajectory(tmp_path / RUN_TRAJECTORY, times, estimate)
    write_tum_trajectory(tmp_path / RUN_TRAJECTORY_GT, times, truth)
    errors = script.position_errors(tmp_path)
    assert np.allclose(errors, 0.1 * np.arange(30), atol=1e-6)
    line = script.profile("off", tmp_path, 10)
    assert line == "off: position error (cm) by frame 0:0.00 10:1.00 20:2.00"
    cells = script.row("off", tmp_path, 20, {"ate_rmse_cm": 0.5}, 60.0).split(" | ")
    assert cells[3:5] == ["2.00", "2.90"]  # back at the start (frame 20), the largest


def test_settings_entries_expand_off_and_on() -> None:
    script = load_script(SCRIPT)
    assert script.expand("off") == ()
    assert script.expand("on,seed=1") == ("mapping.loops.enabled=true", "seed=1")
    assert script.expand("seed=2,mapping.every=4") == ("seed=2", "mapping.every=4")


def test_a_bad_setting_stops_before_any_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    script = load_script(SCRIPT)
    data = tmp_path / "data"
    data.mkdir()
    (data / "synth.json").write_text('{"bound": [[-1, 1], [-1, 1], [-1, 1]]}')  # as written
    with pytest.raises(SystemExit) as stop:
        script.main(["--out", str(tmp_path), "--settings", "on", "mapping.no_such_key=1"])
    assert stop.value.code == 2
    error = capsys.readouterr().err
    assert error.startswith("loop_closure.py: ") and "no_such_key" in error
    assert error.count("\n") == 1
    assert not (tmp_path / "run-0").exists()
