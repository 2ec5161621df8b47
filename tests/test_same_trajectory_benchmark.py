"""benchmarks/same_trajectory.py: one config run by two commits, poses compared."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from eslam.synthetic import read_synthetic_bound
from eslam.testing.scripts import load_script
from tests.conftest import TINY

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "same_trajectory.py"


@pytest.fixture(scope="module")
def script():
    return load_script(SCRIPT)


@pytest.mark.slow
def test_head_against_the_working_tree_runs_both_and_compares(
    script, tiny_sequence: Path, capsys
) -> None:
    bound = f"scene.bound={read_synthetic_bound(tiny_sequence)}"
    overrides = [bound, *TINY, "output.checkpoint_every=100"]
    status = script.main(
        ["--base", "HEAD", "--config", "demo.yaml", "--data", str(tiny_sequence), *overrides]
    )
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == 12 and result["ate_cm"] > 0 and result["ate_base_cm"] > 0
    assert (status == 0) == (result["max_position_diff_m"] <= 1e-6)
    changed = subprocess.run(
        ["git", "status", "--porcelain", "--", "eslam", "configs"],
        cwd=SCRIPT.parents[1],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    if not changed:  # the working tree runs HEAD's code (CI's clean clone): same poses,
        # up to the float32 rounding two processes may differ by (test_run_seams.py)
        assert status == 0 and result["max_position_diff_m"] <= 1e-6


def test_a_difference_beyond_the_tolerance_fails(script, tmp_path: Path, monkeypatch, capsys):
    def differing(base, config, data, overrides):
        return {"frames": 3, "ate_base_cm": 1.0, "ate_cm": 1.2, "max_pose_element_diff": 2e-3,
                "max_position_diff_m": 2e-3}  # fmt: skip

    monkeypatch.setattr(script, "compare", differing)
    arguments = ["--base", "HEAD", "--config", "demo.yaml", "--data", str(tmp_path)]
    assert script.main(arguments) == 1
    assert script.main([*arguments, "--tolerance", "0.01"]) == 0
    with pytest.raises(SystemExit) as stop:
        script.main(["--base", "HEAD", "--config", "nope.yaml", "--data", str(tmp_path)])
    assert stop.value.code == 2 and "configs/nope.yaml does not exist" in capsys.readouterr().err
