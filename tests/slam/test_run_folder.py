"""Run folders that survive every early stop: resume from frame 0, absolute data paths,
the input fingerprint, moved data, the single-writer lock, and eval of a stopped run."""

from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from eslam.cli import EXIT_INTERRUPTED, EXIT_USER_ERROR, main
from eslam.config import load_config
from eslam.errors import InputError, RunInterrupted
from eslam.io.run_lock import LOCK_NAME, acquire, release
from eslam.slam.loop import RunLoop
from eslam.slam.session import run_slam
from eslam.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
from eslam.workflows.demo import DEMO_CONFIG
from tests.conftest import TINY, TINY_FRAMES, tiny_config
from tests.slam.test_run_seams import Recorder

pytestmark = pytest.mark.slow  # integration: whole runs (still run in CI)


def _run_args(sequence: Path, out: Path, *extra: str) -> list[str]:
    bound = read_synthetic_bound(sequence)
    return ["run", str(DEMO_CONFIG), "--data", str(sequence), "--out", str(out),
            f"scene.bound={bound}", *TINY, *extra]  # fmt: skip


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The error line, the only one; eval's closed stage bars may stand before it."""
    err = capsys.readouterr().err.strip()
    lines = err.splitlines()
    assert lines and "Traceback" not in err
    assert [line for line in lines if line.startswith("eslam ")] == lines[-1:]
    return lines[-1]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def _stop_first_frame(monkeypatch: pytest.MonkeyPatch, error: BaseException) -> None:
    def fail(self, frame):
        raise error

    monkeypatch.setattr(RunLoop, "process", fail)


def test_a_stop_before_the_first_frame_is_no_dead_end(
    tiny_sequence: Path,
    tiny_run,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "run"
    # Ctrl-C (or SIGTERM) while the first frame is being tracked or mapped
    with monkeypatch.context() as patch:
        _stop_first_frame(patch, KeyboardInterrupt())
        assert main(_run_args(tiny_sequence, out)) == EXIT_INTERRUPTED
    err = _one_line(capsys)
    assert "before the first frame was complete" in err and f"`eslam resume {out}`" in err
    assert (out / "config.yaml").is_file() and not (out / "map.pt").exists()
    assert not (out / LOCK_NAME).exists()
    # an input error in the first frame says the same
    with monkeypatch.context() as patch:
        _stop_first_frame(patch, InputError(tiny_sequence / "x.png", "unreadable"))
        assert main(["resume", str(out)]) == EXIT_USER_ERROR
    err = _one_line(capsys)
    assert "x.png: unreadable" in err and f"`eslam resume {out}`" in err
    # `eslam run` starts such a folder again without --overwrite ...
    again = tmp_path / "again"
    shutil.copytree(out, again)
    assert main(_run_args(tiny_sequence, again, "output.mesh=false", "--max-frames=1")) == 0
    assert json.loads((again / "metrics.json").read_text())["frames"] == 1
    # ... and `eslam resume` starts it at frame 0 and finishes it exactly
    assert main(["resume", str(out)]) == 0
    resumed = run_slam(load_config(out / "config.yaml"), out, resume=True)  # nothing left
    np.testing.assert_allclose(resumed.poses, tiny_run.poses, rtol=0, atol=1e-7)
    assert "no frame was saved before: the run starts at frame 0" in (out / "log.txt").read_text()


def test_resume_finds_moved_data_and_refuses_changed_data(
    tiny_sequence: Path,
    tiny_run,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    shutil.copytree(tiny_sequence, tmp_path / "data")
    monkeypatch.chdir(tmp_path)
    # started from tmp_path with a relative data path, interrupted after 6 frames
    with pytest.raises(RunInterrupted, match="interrupted after 6 frames"):
        run_slam(tiny_config(Path("data")), "run", observers=[Recorder(interrupt_at_mapping=6)])
    run = tmp_path / "run"
    assert load_config(run / "config.yaml").data.path == str(tmp_path / "data")
    assert json.loads((run / "input.json").read_text())["frames"] == TINY_FRAMES
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    # the interrupted run has its trajectory and metrics: eval scores it from anywhere
    assert main(["eval", str(run), "--views", "0"]) == 0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["frames"] == 6 and metrics["ate_frames"] == 6 and metrics["rpe_pairs"] == 5
    capsys.readouterr()

    saved = _snapshot(run)
    size = (80, 60)
    for frames, words in ((14, "it grew from 12 to 14 frames"), (10, "it shrank from 12 to 10")):
        other = tmp_path / f"other{frames}"
        write_synthetic_sequence(other, SynthConfig(frames=frames, width=size[0], height=size[1],
                                                    seed=3))  # fmt: skip
        assert main(["resume", str(run), "--data", str(other)]) == EXIT_USER_ERROR
        err = _one_line(capsys)
        assert words in err and f"eslam resume {run} --data PATH" in err
    changed = tmp_path / "changed"
    shutil.copytree(tmp_path / "data", changed)
    last = changed / "results" / f"depth{TINY_FRAMES - 1:06d}.png"
    last.write_bytes(last.read_bytes() + b"\0")
    assert main(["resume", str(run), "--data", str(changed)]) == EXIT_USER_ERROR
    assert f"results/depth{TINY_FRAMES - 1:06d}.png (" in _one_line(capsys)
    assert _snapshot(run) == saved, "a refused resume changes nothing"

    # the data moved: resume says where it looked; --data (relative here) finds it
    (tmp_path / "data").rename(tmp_path / "moved")
    assert main(["resume", str(run)]) == EXIT_USER_ERROR
    assert "--data" in _one_line(capsys)
    with monkeypatch.context() as patch:  # Ctrl-C while the final mesh is extracted
        import eslam.mesh.extract

        def interrupted(*args, **kwargs):
            raise KeyboardInterrupt

        patch.setattr(eslam.mesh.extract, "extract_mesh", interrupted)
        assert main(["resume", str(run), "--data", "../moved"]) == EXIT_INTERRUPTED
    err = _one_line(capsys)
    assert f"after {TINY_FRAMES} frames, saved in {run} (continue with `eslam resume {run}`)" in err
    assert load_config(run / "config.yaml").data.path == str(tmp_path / "moved")
    assert main(["resume", str(run)]) == 0  # the new location was recorded
    resumed = json.loads((run / "metrics.json").read_text())
    assert resumed["frames"] == TINY_FRAMES and (run / "mesh.ply").is_file()
    assert resumed["ate_rmse_cm"] == pytest.approx(tiny_run.metrics["ate_rmse_cm"], abs=1e-6)
    # eval with a relative GT mesh and the data found through config.yaml's absolute path
    gt_mesh = Path("..") / "moved" / "mesh.ply"
    wrong = ["--gt-mesh", str(gt_mesh), "--views", "0", "--data", str(changed)]
    assert main(["eval", str(run), *wrong]) == EXIT_USER_ERROR  # eval checks the data too
    assert "is not the input the run in" in _one_line(capsys)
    assert main(["eval", str(run), "--gt-mesh", str(gt_mesh), "--samples", "20000",
                 "--views", "0"]) == 0  # fmt: skip
    assert "accuracy_cm" in json.loads((run / "metrics.json").read_text())


def test_a_live_run_holds_its_folder_and_a_dead_ones_lock_is_taken_over(
    tiny_sequence: Path, tiny_run, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    shutil.copytree(tiny_run.run_dir, run)
    lock = acquire(run, "test")  # a run of this (live) process is writing the folder
    saved = _snapshot(run)
    try:
        assert main(_run_args(tiny_sequence, run, "--overwrite")) == EXIT_USER_ERROR
        assert "a run is still writing this folder (pid" in _one_line(capsys)
        assert main(["resume", str(run)]) == EXIT_USER_ERROR
        assert "a run is still writing this folder" in _one_line(capsys)
        assert _snapshot(run) == saved
    finally:
        release(lock)
    # a run killed without a chance to clean up leaves its lock: the next run takes it over
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = {"pid": dead.pid, "host": socket.gethostname(), "started": 0.0}
    (run / LOCK_NAME).write_text(json.dumps(stale))
    assert main(["resume", str(run)]) == 0
    assert f"took over the lock {run / LOCK_NAME}" in (run / "log.txt").read_text()
    assert not (run / LOCK_NAME).exists()


def _start(args: list[str]) -> subprocess.Popen:
    code = "import sys; from eslam.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.Popen(
        [sys.executable, "-c", code, *args],
        stderr=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[2],
    )


def _wait_for(path: Path, process: subprocess.Popen, timeout: float = 300.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert process.poll() is None, process.communicate()[1]
        assert time.monotonic() < deadline, f"{path} did not appear"
        time.sleep(0.05)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigterm_stops_a_real_run_with_its_frames_saved(
    tiny_sequence: Path, tmp_path: Path
) -> None:
    # before the first frame is complete: nothing to save, the message names resume
    early = tmp_path / "early"
    process = _start(_run_args(tiny_sequence, early, "threads=1"))
    _wait_for(early / "config.yaml", process)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == EXIT_INTERRUPTED, err
    assert f"(continue with `eslam resume {early}`)" in err and "Traceback" not in err
    assert not (early / "map.pt").exists() and not (early / LOCK_NAME).exists()
    # after the first checkpoint (frame 2): the completed frames are saved, lock released
    late = tmp_path / "late"
    process = _start(_run_args(tiny_sequence, late, "threads=1", "output.checkpoint_every=2"))
    _wait_for(late / "map.pt", process)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == EXIT_INTERRUPTED, err
    assert "saved in" in err and f"(continue with `eslam resume {late}`)" in err
    frames = json.loads((late / "metrics.json").read_text())["frames"]
    assert len(np.loadtxt(late / "trajectory.txt", ndmin=2)) == frames >= 2
    assert not (late / LOCK_NAME).exists()
