"""benchmarks/registration_check.py: on exact synthetic frames the loop registration
stays at the ground truth's relative pose; bad pairs get one line and exit 2."""

from __future__ import annotations

from pathlib import Path

from eslam.synthetic import SynthConfig, SyntheticSequence
from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "registration_check.py"


def test_exact_frames_register_at_the_truth(tiny_sequence: Path, capsys) -> None:
    script = load_script(SCRIPT)
    sequence = SyntheticSequence(SynthConfig(frames=12, width=120, height=90))
    ((_, _, cm, degrees, inliers, _),) = script.check_pairs(sequence, [(10, 0)])
    assert cm < 0.2 and degrees < 0.1 and inliers > 0.8
    code = script.main(["--config", "demo", "--data", str(tiny_sequence), "--pairs", "99:0"])
    assert code == 2
    assert "pairs must be i:j" in capsys.readouterr().err
