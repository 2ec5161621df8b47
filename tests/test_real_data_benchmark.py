"""benchmarks/real_data.py: each run of a case gets its own folder, a tracker named
twice included (the second run must not overwrite the first's timings, which the
table reads after all runs)."""

from __future__ import annotations

from pathlib import Path

from eslam.testing.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "real_data.py"


def test_a_tracker_named_twice_runs_into_two_folders(tmp_path: Path, monkeypatch) -> None:
    real_data = load_script(SCRIPT)
    folders: list[Path] = []

    def fake_run(config, out, **kwargs):
        folders.append(Path(out))
        return real_data.RunResult(run_dir=Path(out), poses=None, metrics={"frames": 0})

    monkeypatch.setattr(real_data, "run_slam", fake_run)
    methods = ["hybrid", "render", "hybrid", "hybrid"]
    args = real_data.parse_args(
        ["--device", "cpu", "--out", str(tmp_path), "--cases", "room0-paper", "--methods", *methods]
    )
    case = next(c for c in real_data.CASES if c.name == "room0-paper")
    real_data.run_methods(case, args.methods, args)
    assert [f.name for f in folders] == [
        "room0-paper-hybrid",
        "room0-paper-render",
        "room0-paper-hybrid-2",
        "room0-paper-hybrid-3",
    ]


def test_overrides_may_come_before_options() -> None:
    real_data = load_script(SCRIPT)
    args = real_data.parse_args(["--device", "cpu", "a.b=1", "--cases", "demo", "--methods", "sdf"])
    assert args.overrides == ["a.b=1"]
    assert args.cases == ["demo"] and args.methods == ["sdf"]
