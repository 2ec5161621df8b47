"""eslam sweep and eslam table: a 2-variant x 2-seed grid of tiny runs (plus a variant
that fails), on the local backend and on Ray; sweep files' checks; the shipped sweeps."""

from __future__ import annotations

import json
import os
import shutil
import statistics
import tempfile
from pathlib import Path

import pytest
import yaml

from eslam.cli import main
from eslam.errors import ConfigError, InputError
from eslam.testing.tiny import TINY_SETTINGS
from eslam.workflows.sweep import _run_in_processes, run_cell, run_sweep, worker_lost
from eslam.workflows.sweep_cells import CELL_FILE, is_finished, plan_cells
from eslam.workflows.sweep_file import load_sweep
from eslam.workflows.table import TABLE_METRICS, write_table

REPO = Path(__file__).resolve().parents[2]
SHIPPED = sorted((REPO / "sweeps").glob("*.yaml"))

CELL_SETTINGS = [
    *TINY_SETTINGS,
    "data.max_frames=3",
    "mapping.every=1",
    "mapping.first_iterations=5",
    "mapping.iterations=2",
    "tracking.render.iterations=2",
    "output.mesh=false",
]
"""A cell in about 2 s: three frames of the tiny sequence, few iterations, no mesh."""

GOOD = ("full", "nopose")
SEEDS = (0, 1)


def write_sweep(path: Path, data: Path, **more: object) -> Path:
    sweep = {
        "base": "demo",
        "datasets": [{"name": "tiny", "data": str(data)}],
        "seeds": list(SEEDS),
        "variants": {
            "full": [],
            "nopose": ["mapping.optimise_poses=false"],
            "broken": ["data.start=50"],  # past the sequence's end: fails at once
        },
        "overrides": CELL_SETTINGS,
        "resources": {"cpus": 1, "gpus": 0},
        **more,
    }
    path.write_text(yaml.safe_dump(sweep, sort_keys=False), encoding="utf-8")
    return path


def cell_metrics(out: Path) -> dict[tuple[str, int], dict]:
    return {
        (variant, seed): json.loads(
            (out / "tiny" / variant / f"seed{seed}" / "metrics.json").read_text()
        )
        for variant in GOOD
        for seed in SEEDS
    }


@pytest.fixture(scope="module")
def local_sweep(tiny_sequence: Path, tmp_path_factory: pytest.TempPathFactory):
    """The grid run once on the local backend, one cell after another."""
    folder = tmp_path_factory.mktemp("sweep")
    sweep_file = write_sweep(folder / "sweep.yaml", tiny_sequence)
    out = folder / "out"
    summary = run_sweep(load_sweep(sweep_file), out, progress=False)
    return sweep_file, out, summary


def test_local_sweep_runs_every_cell_and_records_failures(local_sweep) -> None:
    _, out, summary = local_sweep
    statuses = {outcome.cell: outcome.status for outcome in summary.outcomes}
    assert statuses == {
        **{f"tiny/{v}/seed{s}": "done" for v in GOOD for s in SEEDS},
        **{f"tiny/broken/seed{s}": "failed" for s in SEEDS},
    }
    assert "2 failed" in summary.text()
    for variant in GOOD:
        for seed in SEEDS:
            cell = out / "tiny" / variant / f"seed{seed}"
            assert json.loads((cell / CELL_FILE).read_text())["status"] == "done"
            config = yaml.safe_load((cell / "config.yaml").read_text())
            assert config["seed"] == seed and config["threads"] == 1
            assert config["mapping"]["optimise_poses"] is (variant == "full")
            assert (cell / "report.md").is_file()  # evaluated like eslam eval
    failed = json.loads((out / "tiny" / "broken" / "seed0" / CELL_FILE).read_text())
    assert failed["status"] == "failed"
    assert "data.start=50" in failed["error"] and "\n" not in failed["error"]
    metrics = cell_metrics(out)
    assert metrics[("full", 0)]["ate_rmse_cm"] != metrics[("full", 1)]["ate_rmse_cm"]  # seeds


def test_table_aggregates_the_cells_metrics(local_sweep) -> None:
    _, out, _ = local_sweep
    result = write_table(out)
    metrics = cell_metrics(out)
    rows = json.loads((out / "table.json").read_text())
    assert rows == json.loads(json.dumps(list(result.rows)))
    keys = {(row["variant"], row["metric"]) for row in rows}
    for variant in GOOD:
        for metric in ("ate_rmse_cm", "ate_mean_cm", "fpt_s"):
            assert (variant, metric) in keys
    for row in rows:
        assert row["dataset"] == "tiny" and row["variant"] in GOOD and row["n"] == 2
        values = [metrics[(row["variant"], seed)][row["metric"]] for seed in SEEDS]
        assert row["mean"] == pytest.approx(statistics.mean(values), rel=1e-12)
        assert row["std"] == pytest.approx(statistics.stdev(values), rel=1e-12)
        assert row["paper"] is None  # the sweep names no paper experiment
    csv_lines = (out / "table.csv").read_text().splitlines()
    assert csv_lines[0].startswith("dataset,variant,metric,mean,std,n")
    assert len(csv_lines) == len(rows) + 1
    markdown = (out / "table.md").read_text()
    full_rmse = next(r for r in rows if r["variant"] == "full" and r["metric"] == "ate_rmse_cm")
    assert f"| full | 2 | {full_rmse['mean']:.2f} ± {full_rmse['std']:.2f} |" in markdown
    assert "tiny/broken/seed0: failed" in markdown
    plotted = {path.stem for path in (out / "plots").glob("*.png")}
    assert plotted == {metric for metric, _ in TABLE_METRICS if (GOOD[0], metric) in keys}


def test_resume_skips_finished_cells_and_retries_failed_ones(local_sweep) -> None:
    sweep_file, out, _ = local_sweep
    finished = [out / "tiny" / v / f"seed{s}" for v in GOOD for s in SEEDS]
    stamps = {
        (path, name): (path / name).stat().st_mtime_ns
        for path in finished
        for name in ("metrics.json", "config.yaml", CELL_FILE, "trajectory.txt")
    }
    failed_cell = out / "tiny" / "broken" / "seed0" / CELL_FILE
    failed_stamp = failed_cell.stat().st_mtime_ns
    summary = run_sweep(load_sweep(sweep_file), out, progress=False)
    assert summary.count("skipped") == 4 and summary.count("failed") == 2
    for path in finished:
        for name in ("metrics.json", "config.yaml", CELL_FILE, "trajectory.txt"):
            assert (path / name).stat().st_mtime_ns == stamps[(path, name)], (
                f"{path}/{name} rewritten"
            )
    assert failed_cell.stat().st_mtime_ns != failed_stamp  # retried and recorded again
    # A changed config is not the finished run: those cells would run again.
    assert all(is_finished(c) for c in plan_cells(load_sweep(sweep_file), out) if c.variant in GOOD)
    sweep = yaml.safe_load(sweep_file.read_text())
    changed = sweep_file.parent / "changed.yaml"
    changed.write_text(
        yaml.safe_dump({**sweep, "overrides": [*CELL_SETTINGS, "mapping.iterations=3"]})
    )
    assert not any(is_finished(cell) for cell in plan_cells(load_sweep(changed), out))


def test_changed_evaluation_settings_evaluate_again_without_running(
    local_sweep, tmp_path: Path
) -> None:
    sweep_file, out, _ = local_sweep
    shutil.copytree(out / "tiny" / "full" / "seed0", tmp_path / "tiny" / "full" / "seed0")
    sweep = yaml.safe_load(sweep_file.read_text())
    evaluated = tmp_path / "evaluated.yaml"
    evaluated.write_text(yaml.safe_dump({**sweep, "evaluation": {"seed": 1}}, sort_keys=False))
    cell = next(c for c in plan_cells(load_sweep(evaluated), tmp_path) if c.variant == "full")
    trajectory = cell.run_dir / "trajectory.txt"
    before = trajectory.stat().st_mtime_ns
    assert not is_finished(cell)
    assert run_cell(cell).status == "done"
    assert trajectory.stat().st_mtime_ns == before  # not run again
    recorded = json.loads((cell.run_dir / CELL_FILE).read_text())
    assert recorded["evaluation"]["seed"] == 1 and is_finished(cell)


def test_ctrl_c_keeps_finished_cells_and_marks_the_running_one(
    local_sweep, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import eslam.workflows.sweep as sweep_module

    sweep_file, local_out, _ = local_sweep
    out = tmp_path / "out"
    shutil.copytree(local_out, out)
    shutil.rmtree(out / "tiny" / "nopose" / "seed1")
    kept = {p: p.stat().st_mtime_ns for p in out.glob("tiny/full/seed*/metrics.json")}

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "run_slam", interrupted)
    with pytest.raises(KeyboardInterrupt, match="3 of 6 cells finished and kept"):
        run_sweep(load_sweep(sweep_file), out, progress=False)
    status = json.loads((out / "tiny" / "nopose" / "seed1" / CELL_FILE).read_text())
    assert status["status"] == "interrupted"
    assert {p: p.stat().st_mtime_ns for p in kept} == kept


def test_cli_sweep_exit_status_and_table(local_sweep, capsys: pytest.CaptureFixture) -> None:
    sweep_file, out, _ = local_sweep
    assert main(["sweep", str(sweep_file), "--out", str(out), "--datasets", "tiny"]) == 1
    printed = capsys.readouterr().out
    assert "6 cells, 0 run, 4 finished before, 2 failed" in printed
    assert main(["table", str(out), "--no-plots"]) == 0
    assert "table.json" in capsys.readouterr().out
    assert main(["sweep", str(sweep_file), "--out", str(out), "--datasets", "nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no dataset named 'nope'" in err and str(sweep_file) in err
    dry = ["sweep", str(sweep_file), "--out", str(out), "--variants", "full", "--dry-run"]
    assert main(dry) == 0
    planned = json.loads(capsys.readouterr().out)
    assert [(c["cell"], c["finished"]) for c in planned] == [
        ("tiny/full/seed0", True),
        ("tiny/full/seed1", True),
    ]
    assert main([*dry[:-3], "--variants", "ful"]) == 2
    assert "no variant named 'ful' (it has: full, nopose, broken)" in capsys.readouterr().err


@pytest.mark.slow
def test_worker_processes_record_their_cells(local_sweep) -> None:
    """--jobs 2: cells run in spawned worker processes (here the failing one, the
    finished cells are skipped by the driver); the outcome comes back and is recorded."""
    sweep_file, out, _ = local_sweep
    sweep = load_sweep(sweep_file)
    cells = [cell for cell in plan_cells(sweep, out) if cell.name == "tiny/broken/seed1"]
    outcomes = []
    _run_in_processes(cells, 2, outcomes.append)
    assert [(o.cell, o.status) for o in outcomes] == [("tiny/broken/seed1", "failed")]
    assert "data.start=50" in outcomes[0].error
    recorded = json.loads((out / "tiny" / "broken" / "seed1" / CELL_FILE).read_text())
    assert recorded["status"] == "failed" and recorded["error"] == outcomes[0].error


@pytest.mark.slow
def test_ray_backend_runs_the_same_grid(local_sweep, tmp_path: Path) -> None:
    """The local grid's output with one finished cell removed, resumed on Ray: that cell
    runs in a Ray task (the same numbers as the local run: same seed, one thread), the
    failing cells fail there too, the rest are skipped; the table matches the cells."""
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'eslam[cluster]')")
    sweep_file, local_out, _ = local_sweep
    out = tmp_path / "out"
    shutil.copytree(local_out, out)
    shutil.rmtree(out / "tiny" / "full" / "seed1")
    # Ray's socket paths must stay under 107 bytes: a short folder, not pytest's tmp_path.
    temp_dir = tempfile.mkdtemp(prefix="ray", dir="/tmp")
    ray.init(
        address="local",
        num_cpus=1,  # one worker process; no GPUs declared, and the sweep asks for none
        include_dashboard=False,
        _temp_dir=temp_dir,
        runtime_env={"env_vars": {"PYTHONPATH": str(REPO), "OMP_WAIT_POLICY": "PASSIVE"}},
    )
    try:
        summary = run_sweep(load_sweep(sweep_file), out, backend="ray", progress=False)
    finally:
        ray.shutdown()
        shutil.rmtree(temp_dir, ignore_errors=True)
    statuses = {outcome.cell: outcome.status for outcome in summary.outcomes}
    assert statuses["tiny/full/seed1"] == "done"
    assert summary.count("skipped") == 3 and summary.count("failed") == 2
    metrics, local = cell_metrics(out), cell_metrics(local_out)
    for key in ("ate_rmse_cm", "ate_mean_cm"):
        assert metrics[("full", 1)][key] == pytest.approx(local[("full", 1)][key], rel=1e-6)
    for row in write_table(out, plots=False).rows:
        values = [metrics[(row["variant"], seed)][row["metric"]] for seed in SEEDS]
        assert row["mean"] == pytest.approx(statistics.mean(values), rel=1e-12)
        assert row["n"] == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"seedz": [0]}, "seedz: unknown key (did you mean 'seeds'?"),
        ({"seeds": [0, 0]}, "seeds: lists a seed twice"),
        ({"seeds": -1}, "seeds: a count of seeds must be >= 1"),
        ({"variants": {"a b": []}}, "variants.a b: must be a folder-safe name"),
        ({"variants": {"v": "mapping.iterations"}}, "variants.v: must be a list of key=value"),
        ({"variants": {"v": {"overrides": [], "paper": "z"}}}, "variants.v.paper: must be one of"),
        ({"resources": {"cpus": 0}}, "resources.cpus: must be an integer >= 1"),
        ({"resources": {"gpu": 1}}, "resources.gpu: unknown key (did you mean 'gpus'?"),
        ({"evaluation": {"samples": 0}}, "evaluation of 'tiny': --samples must be >= 1"),
        (
            {"overrides": ["mapping.iterationz=3"]},
            "dataset 'tiny', variant 'full': command line: unknown key 'mapping.iterationz'",
        ),
        ({"datasets": [{"name": "x"}]}, "datasets[0].data: is missing"),
        (
            {"datasets": [{"name": "x", "data": "${ESLAM_NOT_SET_ANYWHERE}"}]},
            "ESLAM_NOT_SET_ANYWHERE",
        ),
        ({"base": "nosuchconfig"}, "base: nosuchconfig is neither a file"),
    ],
)
def test_bad_sweep_files_are_one_line_config_errors(
    tiny_sequence: Path, tmp_path: Path, change: dict, message: str
) -> None:
    path = write_sweep(tmp_path / "bad.yaml", tiny_sequence, **change)
    os.environ.pop("ESLAM_NOT_SET_ANYWHERE", None)
    with pytest.raises(ConfigError) as error:
        plan_cells(load_sweep(path), tmp_path / "out")
    text = str(error.value)
    assert text.startswith(f"{path}: ") and message in text and "\n" not in text


def test_missing_input_and_a_mesh_metric_without_a_mesh_are_refused(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    path = write_sweep(
        tmp_path / "s.yaml", tiny_sequence, datasets=[{"name": "t", "data": "missing"}]
    )
    with pytest.raises(InputError, match="sequence folder not found"):
        run_sweep(load_sweep(path), tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()  # nothing written before the check
    dataset = {"name": "t", "data": str(tiny_sequence), "gt_mesh": "mesh.ply"}
    path = write_sweep(tmp_path / "s.yaml", tiny_sequence, datasets=[dataset])
    with pytest.raises(ConfigError, match=r"sets output\.mesh=false"):
        plan_cells(load_sweep(path), tmp_path / "out")


def test_paths_expand_variables_relative_to_the_sweep_file(
    tiny_sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    dataset = {"name": "t", "data": "${SWEEP_TEST_ROOT:-nowhere}/data"}
    path = write_sweep(tmp_path / "s.yaml", tiny_sequence, datasets=[dataset])
    cells = plan_cells(load_sweep(path), tmp_path / "out")
    assert cells[0].config.data.path == str(tmp_path / "nowhere" / "data")
    monkeypatch.setenv("SWEEP_TEST_ROOT", str(tiny_sequence.parent))
    cells = plan_cells(load_sweep(path), tmp_path / "out")
    assert cells[0].config.data.path == str(tiny_sequence)
    assert cells[0].config.scene.bound is not None  # a synthetic scene's exact bound
    assert cells[0].run_dir == tmp_path / "out" / "t" / "full" / "seed0"
    extra = plan_cells(load_sweep(path), tmp_path / "out", extra=["mapping.iterations=3"])
    assert {cell.config.mapping.iterations for cell in extra} == {3}  # eslam sweep key=value
    # A worker that died (killed, out of memory) leaves its cell recorded as failed.
    outcome = worker_lost(cells[0], RuntimeError("A process in the process pool was terminated"))
    recorded = json.loads((cells[0].run_dir / CELL_FILE).read_text())
    assert outcome.status == recorded["status"] == "failed"
    assert recorded["error"] == outcome.error and "worker process" in outcome.error
    assert not is_finished(cells[0])


@pytest.mark.parametrize("sweep_file", SHIPPED, ids=lambda path: path.name)
def test_shipped_sweeps_parse_and_resolve_every_cell(sweep_file: Path) -> None:
    sweep = load_sweep(sweep_file)
    cells = plan_cells(sweep, "out")  # every dataset's and variant's config resolves
    assert len(cells) == len(sweep.datasets) * len(sweep.variants) * len(sweep.seeds)
    assert sweep.resources.gpus == 0  # GPU requests are opt-in (they wait forever without)
    papered = [variant for variant in sweep.variants if variant.paper is not None]
    assert papered, "a shipped sweep repeats the paper's experiments"


def test_shipped_ablations_are_the_papers_rows() -> None:
    sweep = load_sweep(REPO / "sweeps" / "ablations.yaml")
    assert [variant.paper for variant in sweep.variants] == ["full", *"abcdefgh"]
    iterations = load_sweep(REPO / "sweeps" / "iterations.yaml")
    assert [variant.paper for variant in iterations.variants] == ["full", "x2", "x10"]


def test_sweep_backends_are_a_registry_the_cli_offers(tmp_path: Path) -> None:
    """The backends by name: the CLI's --backend choices are the registry's names (the
    CLI does not import the sweep module to build its parser); an unknown name is a
    ConfigError naming the choices, before anything is written."""
    from eslam.cli import sweep as sweep_command
    from eslam.workflows.sweep import SWEEP_BACKENDS

    assert SWEEP_BACKENDS.names() == ("local", "ray")
    assert sweep_command.BACKENDS == SWEEP_BACKENDS.names()
    sweep = load_sweep(write_sweep(tmp_path / "sweep.yaml", tmp_path))
    with pytest.raises(ConfigError, match=r"unknown backend 'slurm' \(choose one of: local, ray\)"):
        run_sweep(sweep, tmp_path / "out", backend="slurm", progress=False)
    assert not (tmp_path / "out").exists()
