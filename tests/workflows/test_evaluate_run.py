"""`eslam eval` on a tiny synthetic run: every metric, culled mesh, report and plots."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from eslam.cli import EXIT_USER_ERROR, main
from eslam.config import load_config
from eslam.io.mesh_files import read_mesh_ply
from eslam.slam.run.remesh import remesh_run
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY

ALL_KEYS = {
    "ate_rmse_cm",
    "ate_mean_cm",
    "ate_median_cm",
    "ate_max_cm",
    "accuracy_cm",
    "completion_cm",
    "completion_ratio_pct",
    "precision_pct",
    "recall_pct",
    "f1_pct",
    "depth_l1_cm",
}


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("eval")
    data = root / "data"
    write_synthetic_sequence(data, SynthConfig(frames=10, width=80, height=60, seed=3))
    bound = read_synthetic_bound(data)
    config = load_config(DEMO_CONFIG, [f"data.path={data}", f"scene.bound={bound}", *TINY])
    result = run_slam(config, root / "run")
    # TINY meshes at 10 cm for speed; a cell is meshed only where all its corners were
    # observed (up to T = 6 cm behind the depth), which drops most cells at 10 cm
    remesh_run(result.run_dir, resolution=0.03)
    return result.run_dir, data / "mesh.ply"


def _eval(run_dir: Path, *extra: str) -> int:
    return main(["eval", str(run_dir), "--samples", "50000", "--views", "15", *extra])


def test_eval_writes_every_metric_report_and_plots(run, capsys) -> None:
    run_dir, gt_mesh = run
    assert _eval(run_dir, "--gt-mesh", str(gt_mesh), "--max-unobserved", "0.5") == 0
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert ALL_KEYS <= set(metrics)
    assert metrics["frames"] == 10  # the run's own metrics are kept
    # a coarse 10-frame map (12 cm planes) measured 0.95 / 2.4 cm, 88 %, F1 59 %,
    # depth L1 4.0 cm (15 views): a broken cull, frame or sampling would be far off
    assert metrics["accuracy_cm"] < 2.0 and metrics["completion_cm"] < 4.0
    assert metrics["completion_ratio_pct"] > 80.0 and metrics["f1_pct"] > 40.0
    assert metrics["depth_l1_cm"] < 6.0
    assert metrics["ate_max_cm"] >= metrics["ate_rmse_cm"] >= metrics["ate_median_cm"] * 0.5
    culled, full = read_mesh_ply(run_dir / "mesh_culled.ply"), read_mesh_ply(run_dir / "mesh.ply")
    assert 0 < len(culled.faces) <= len(full.faces)
    report = (run_dir / "report.md").read_text()
    assert "| Accuracy (cm) |" in report and "450,000" not in report and "50,000" in report
    for image in ("trajectory.png", "translation_error.png"):
        assert (run_dir / image).is_file() and f"]({image})" in report
    captured = capsys.readouterr()
    assert "Depth L1" in captured.out
    # minutes of culling, distances and ray casting were silent: a bar per stage
    for stage in ("ATE and plots", "cull mesh.ply", "cull GT mesh", "accuracy and completion"):
        assert stage in captured.err
    assert "10/10 [" in captured.err and "depth L1" in captured.err and "15/15 [" in captured.err
    assert captured.err.endswith("\n")  # every bar closed


def test_reevaluation_drops_stale_metrics_and_nice_culls_less(run) -> None:
    run_dir, gt_mesh = run
    assert _eval(run_dir, "--gt-mesh", str(gt_mesh), "--views", "0") == 0
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert "depth_l1_cm" not in metrics and "accuracy_cm" in metrics
    eslam_faces = len(read_mesh_ply(run_dir / "mesh_culled.ply").faces)
    assert _eval(run_dir, "--gt-mesh", str(gt_mesh), "--views", "0", "--protocol", "nice") == 0
    assert len(read_mesh_ply(run_dir / "mesh_culled.ply").faces) >= eslam_faces
    assert _eval(run_dir) == 0  # ATE only
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert "ate_rmse_cm" in metrics and "accuracy_cm" not in metrics


def test_eval_of_a_folder_that_is_not_a_run(tmp_path: Path, capsys) -> None:
    assert main(["eval", str(tmp_path)]) == EXIT_USER_ERROR
    err = capsys.readouterr().err.strip()
    assert "config.yaml: not found: not a run folder" in err and "\n" not in err


def test_eval_of_a_run_stopped_after_two_frames_says_resume(run, tmp_path: Path, capsys) -> None:
    # issue 15's failure drills: a run interrupted after its 2nd frame was called a
    # folder "assembled from different runs"
    stopped = tmp_path / "stopped"
    shutil.copytree(run[0], stopped)
    for name in ("trajectory.txt", "trajectory_gt.txt"):
        lines = (stopped / name).read_text().splitlines(keepends=True)
        header = [line for line in lines if line.startswith("#")]
        poses = [line for line in lines if not line.startswith("#")]
        (stopped / name).write_text("".join(header + poses[:2]))
    assert main(["eval", str(stopped)]) == EXIT_USER_ERROR
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "trajectory.txt: holds 2 frames, and the ATE needs at least 3" in last
    assert f"eslam resume {stopped}" in last


@pytest.mark.parametrize(
    ("flag", "value"),
    [("--samples", "0"), ("--samples", "-5"), ("--cull-every", "0"), ("--views", "-1")],
)
def test_eval_counts_below_one_are_one_line_exit_2(tmp_path: Path, capsys, flag, value) -> None:
    """Issue 15: `eslam eval --samples 0` / `--cull-every 0` ended in a traceback."""
    with pytest.raises(SystemExit) as stopped:  # argparse's error exit, one line
        main(["eval", str(tmp_path), flag, value])
    assert stopped.value.code == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and flag in err and "Traceback" not in err


def test_evaluation_options_refuse_counts_from_python() -> None:
    from eslam.errors import ConfigError
    from eslam.workflows.evaluate_run import EvaluationOptions

    for bad in ({"samples": 0}, {"cull_every": 0}, {"depth_l1_views": -1}):
        with pytest.raises(ConfigError, match="must be >="):
            EvaluationOptions(**bad)
    with pytest.raises(ConfigError, match="--max-unobserved"):
        EvaluationOptions(max_unobserved_fraction=1.5)


def test_eval_into_a_read_only_run_folder_is_one_line(run, monkeypatch, capsys) -> None:
    """Issue 15: eval outputs that cannot be written were a traceback."""
    import errno
    import os

    from eslam import atomic

    run_dir, _ = run
    before = {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()}

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(atomic.os, "replace", read_only)
    assert _eval(run_dir) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    # the stage bars stay on screen, closed (docs: eslam/workflows/progress.py); the
    # error is the one line after them
    last = err.rstrip("\n").splitlines()[-1]
    assert last.startswith("eslam eval: error:") and "the file system is read-only" in last
    assert str(run_dir) in last and "Traceback" not in err
    monkeypatch.undo()
    after = {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()}
    assert after == before  # nothing half-written, no temporaries left


def test_report_title_names_the_run_folder(run) -> None:
    """The title was "# eslam run run" for a folder named run (the demo's): it names the
    folder as given, parents included."""
    run_dir, _ = run
    assert _eval(run_dir) == 0
    title = (run_dir / "report.md").read_text().splitlines()[0]
    assert title == f"# Evaluation of run {run_dir}"
