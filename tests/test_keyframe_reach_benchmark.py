"""benchmarks/keyframe_reach.py: one mapped keyframe, frames further and further on,
each looked at from its ground-truth pose (the tiny synthetic sequence: on its coarse
80x60 map the SDF tracker settles about 2 cm from the truth, as in
test_sdf_tracking_benchmark.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from eslam.synthetic import read_synthetic_bound
from eslam.testing.scripts import load_script
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "keyframe_reach.py"


def test_a_near_frame_fits_the_first_keyframe_and_stays_near_its_truth(
    tiny_sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    module = load_script(SCRIPT)
    bound = read_synthetic_bound(tiny_sequence)
    module.main(
        [
            "--config", str(DEMO_CONFIG), "--data", str(tiny_sequence),
            "--out", str(tmp_path / "reach"), "--frames", "1,3",
            *TINY, f"scene.bound={bound}",
        ]
    )  # fmt: skip
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert len(rows) == 3  # the header, then one row per frame
    cells = [cell.strip() for cell in rows[1].strip("|").split("|")]
    assert cells[0] == "1" and float(cells[1]) > 0.8 and float(cells[2]) >= 0.5
    inliers, off, failed = (part.strip() for part in cells[3].split("/"))
    millimetres = float(off.split(",")[0])
    assert float(inliers) >= 0.5 and failed == "no" and millimetres < 30.0, rows
