"""Failure drills: issue 15's list of ways a run can go wrong, each run through the real
``eslam`` command as a subprocess, with a markdown table of what happened.

Why: docs/reliability.md promises that every stop either succeeds or ends with one line
and exit status 2 (130 for Ctrl-C / SIGTERM), that nothing saved is lost, and that
``eslam resume`` continues a stopped run to the trajectory an uninterrupted run gives.
The unit tests check each piece in-process; this script checks the whole promise the way
a user meets it (signals to a live process, files broken on disk, a full file system),
so a regression anywhere between the CLI and the disk shows up as a FAIL row.

Each drill records the case, the command, its exit status, whether stderr is one line
without a traceback, and what was checked afterwards (files intact, ``eslam resume``
succeeds, the trajectory equals the uninterrupted run's). A drill whose outcome differs
from the documented one is a FAIL with the detail; the script exits 1 if any drill
fails. Everything is written under ``--work`` (default: a temporary folder): a tiny
synthetic sequence (``eslam.synthetic``, 8 frames of 80x60) and one run folder per drill.

The disk-full and read-only drills mount small tmpfs file systems under ``--work``
(needs root or CAP_SYS_ADMIN); where ``mount`` fails they say so and point to the unit
tests that simulate the same errors.

    python benchmarks/failure_drills.py                 # all drills, table into docs
    python benchmarks/failure_drills.py --no-append --only sigint kill9
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from _machine import REPO, command_line, load_average, machine_lines
from PIL import Image

from eslam.atomic import write_text
from eslam.io.run_lock import LOCK_NAME
from eslam.synthetic import SynthConfig, read_synthetic_bound, write_synthetic_sequence
from eslam.synthetic.sequence import generate_sequence
from eslam.testing import write_folder_sequence
from eslam.testing.tiny import TINY_SETTINGS
from eslam.workflows.demo import DEMO_CONFIG

DEFAULT_DOCS = REPO / "docs" / "reliability.md"
HEADING = "## Failure drills"

FRAMES = 8
"""Frames of the drills' synthetic sequence: enough for checkpoints at 2, 4 and 6."""

TINY = [*TINY_SETTINGS, "output.checkpoint_every=2"]
"""Settings that make a run of the drills' sequence take seconds on one CPU thread (the
first frame maps 60 steps: long enough to be interrupted in)."""

TRAJECTORY_TOLERANCE_M = 1e-6
"""A resumed run's trajectory may differ from the uninterrupted run's by this much."""


@dataclass
class Row:
    """One drill's line of the table."""

    case: str
    command: str = ""
    code: int | None = None
    one_line: bool | None = None
    checks: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    def check(self, ok: bool, good: str, bad: str | None = None) -> bool:
        """Record a check: ``good`` when it holds, else a problem (``bad`` or ``good``)."""
        (self.checks if ok else self.problems).append(good if ok else f"NOT {bad or good}")
        return ok


@dataclass
class Result:
    """What one ``eslam`` subprocess did."""

    args: list[str]
    code: int
    stderr: str
    stdout: str


def stderr_is_one_line(stderr: str) -> bool:
    """The documented stop: no traceback, and stderr ends with the one line of the stop
    (``eslam CMD: ...``), the only such line; closed progress bars (eval's stages) may
    stand before it."""
    lines = [line for line in re.split(r"[\r\n]", stderr) if line.strip()]
    messages = [line for line in lines if line.startswith("eslam")]
    return (
        bool(lines)
        and lines[-1].startswith("eslam")
        and len(messages) == 1
        and ("Traceback" not in stderr)
    )


class Drills:
    """The drills' shared state: the work folder, the sequence, the reference run."""

    def __init__(self, work: Path, threads: int, show: Callable[[str], None]) -> None:
        self.work = work
        self.threads = threads
        self.show = show
        self.env = {
            **os.environ,
            "OMP_WAIT_POLICY": "PASSIVE",
            "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
        }
        self.sequence = work / "sequence"
        self.reference: np.ndarray | None = None
        self.mounts: list[Path] = []

    # --- running eslam -------------------------------------------------------------

    def argv(self, args: list[str]) -> list[str]:
        return [sys.executable, "-m", "eslam", *args]

    def shown(self, args: list[str]) -> str:
        """The command as a user types it, paths under the work folder as $WORK."""
        tiny = [a for a in args if a in TINY or a.startswith(("scene.bound=", "threads="))]
        kept = [a for a in args if a not in tiny]
        text = shlex.join(["eslam", *kept]) + (" $TINY" if tiny else "")
        return text.replace(str(self.work), "$WORK").replace(str(DEMO_CONFIG), "demo.yaml")

    def eslam(self, args: list[str], cwd: Path | None = None, timeout: float = 600) -> Result:
        """Run ``eslam ARGS`` to the end."""
        done = subprocess.run(
            self.argv(args),
            cwd=cwd or self.work,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        return Result(args, done.returncode, done.stderr, done.stdout)

    def start(self, args: list[str], cwd: Path | None = None) -> subprocess.Popen:
        """Start ``eslam ARGS`` in the background."""
        return subprocess.Popen(
            self.argv(args),
            cwd=cwd or self.work,
            env=self.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    def run_args(self, out: Path | str, *extra: str, data: Path | str | None = None) -> list[str]:
        """``eslam run`` of the demo config on the drills' sequence with the tiny settings."""
        bound = json.dumps(read_synthetic_bound(self.sequence)).replace(" ", "")
        return [
            "run", str(DEMO_CONFIG), "--data", str(data or self.sequence), "--out", str(out),
            f"scene.bound={bound}", f"threads={self.threads}", *TINY, *extra,
        ]  # fmt: skip

    def interrupted(
        self,
        row: Row,
        args: list[str],
        wait_for: str,
        how: signal.Signals,
        cwd: Path | None = None,
        frames: int = 0,
    ) -> Result | None:
        """Start ``args``, wait until the run folder holds ``wait_for`` (and a checkpoint
        of at least ``frames`` frames), send ``how``."""
        out = Path(args[args.index("--out") + 1])
        out = out if out.is_absolute() else (cwd or self.work) / out
        process = self.start(args, cwd)
        deadline = time.monotonic() + 300
        while not (out / wait_for).exists() or (frames and self.saved_frames(out) < frames):
            if process.poll() is not None or time.monotonic() > deadline:
                process.kill()
                _, err = process.communicate()
                row.command = f"{self.shown(args)}; {how.name} once {wait_for} exists"
                row.code = process.returncode
                row.problems.append(f"{wait_for} never appeared before the run ended: {err[-300:]}")
                return None
            time.sleep(0.02)
        process.send_signal(how)
        out_text, err = process.communicate(timeout=300)
        row.command = f"{self.shown(args)}; {how.name} once {wait_for} exists"
        row.code = process.returncode
        return Result(args, process.returncode, err, out_text)

    # --- checks ----------------------------------------------------------------------

    def expect(self, row: Row, result: Result, code: int, *needles: str) -> bool:
        """The exit status is ``code``; a failing command's stderr is one line holding
        every needle."""
        if not row.command:
            row.command = self.shown(result.args)
        if row.code is None:
            row.code = result.code
        ok = row.check(result.code == code, f"exit {code}", f"exit {code} (got {result.code})")
        if code != 0:
            row.one_line = stderr_is_one_line(result.stderr)
            if not row.one_line:
                row.problems.append(f"stderr not one line: {result.stderr.strip()[-400:]!r}")
            last = re.split(r"[\r\n]", result.stderr.strip())[-1]
            shown = last.replace(str(self.work), "$WORK")
            row.checks.append(f'said "{shown[:200]}{"..." if len(shown) > 200 else ""}"')
            missing = [needle for needle in needles if needle not in result.stderr]
            if missing:
                row.problems.append(f"message lacks {missing}: {result.stderr.strip()!r}")
            ok = ok and row.one_line and not missing
        elif result.code != 0:
            row.problems.append(f"stderr: {result.stderr.strip()[-400:]!r}")
        return ok

    def saved_frames(self, run: Path) -> int:
        """Frames in the run folder's trajectory.txt (0 when there is none)."""
        path = run / "trajectory.txt"
        return len(np.loadtxt(path, ndmin=2)) if path.exists() else 0

    def same_as_reference(self, row: Row, run: Path) -> bool:
        """trajectory.txt of ``run`` equals the uninterrupted run's."""
        assert self.reference is not None
        path = run / "trajectory.txt"
        if not path.exists():
            return row.check(False, "", "trajectory.txt written")
        poses = np.loadtxt(path, ndmin=2)
        if poses.shape != self.reference.shape:
            return row.check(False, "", f"{len(self.reference)} poses (got {len(poses)})")
        diff = float(np.abs(poses - self.reference).max())
        return row.check(
            diff <= TRAJECTORY_TOLERANCE_M,
            f"trajectory = uninterrupted run's (max diff {diff:.1e})",
            f"trajectory = uninterrupted run's (max diff {diff:.1e} m)",
        )

    def resumes(self, row: Row, run: Path, *extra: str, cwd: Path | None = None) -> bool:
        """``eslam resume RUN`` succeeds and ends on the uninterrupted run's trajectory."""
        result = self.eslam(["resume", str(run), *extra], cwd=cwd)
        if not row.check(result.code == 0, "resume exit 0", f"resume exit 0 (got {result.code})"):
            row.problems.append(f"resume stderr: {result.stderr.strip()[-400:]!r}")
            return False
        folder = run if run.is_absolute() else (cwd or self.work) / run
        row.check(not (folder / LOCK_NAME).exists(), "lock released")
        return self.same_as_reference(row, folder)

    def snapshot(self, folder: Path) -> dict[str, bytes]:
        return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}

    def unchanged(self, row: Row, folder: Path, before: dict[str, bytes]) -> bool:
        after = self.snapshot(folder)
        changed = sorted(n for n in before.keys() | after.keys() if before.get(n) != after.get(n))
        return row.check(not changed, "run folder unchanged", f"run folder unchanged: {changed}")

    def nothing_written(self, row: Row, out: Path) -> bool:
        return row.check(not out.exists(), "no run folder created", "no run folder created")

    # --- data ------------------------------------------------------------------------

    def copy_sequence(self, name: str) -> Path:
        target = self.work / name
        shutil.copytree(self.sequence, target)
        return target

    def depth_files(self, sequence: Path) -> list[Path]:
        return sorted((sequence / "results").glob("depth*.png"))

    def rewrite_depth(self, sequence: Path, change: Callable[[np.ndarray], np.ndarray]) -> None:
        for path in self.depth_files(sequence):
            depth = np.asarray(Image.open(path)).astype(np.int64)
            Image.fromarray(change(depth).astype(np.uint16)).save(path)

    def interrupted_copy(self, name: str) -> Path:
        """A copy of the run stopped after its checkpoint (written by the SIGINT drill)."""
        source = self.work / "sigint-checkpoint-stopped"
        target = self.work / name
        shutil.copytree(source, target)
        return target

    @contextlib.contextmanager
    def tmpfs(self, name: str, options: str) -> Iterator[Path | None]:
        """A tmpfs mounted at WORK/name with ``options``; None where mount is refused."""
        where = self.work / name
        where.mkdir()
        done = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            yield None
            return
        self.mounts.append(where)
        try:
            yield where
        finally:
            subprocess.run(["umount", str(where)], capture_output=True)
            self.mounts.remove(where)

    # --- setup -----------------------------------------------------------------------

    def setup(self) -> None:
        """The sequence and the uninterrupted reference run every resume is compared with."""
        write_synthetic_sequence(
            self.sequence, SynthConfig(frames=FRAMES, width=80, height=60, seed=3)
        )
        result = self.eslam(self.run_args(self.work / "reference"))
        if result.code != 0:
            raise SystemExit(f"the reference run failed: {result.stderr}")
        self.reference = np.loadtxt(self.work / "reference" / "trajectory.txt", ndmin=2)
        self.show(f"reference run: {len(self.reference)} frames")


# --- the drills ------------------------------------------------------------------------
# Each takes the shared Drills and returns its Row; DRILLS lists them in table order.


SIGNAL_NAMES = {
    signal.SIGINT: "Ctrl-C (SIGINT)",
    signal.SIGTERM: "SIGTERM",
    signal.SIGKILL: "kill -9 (SIGKILL)",
}


def _signal_first_frame(how: signal.Signals) -> Callable[[Drills], Row]:
    def drill(d: Drills) -> Row:
        name = SIGNAL_NAMES[how]
        row = Row(f"{name} during the first frame, then resume")
        run = d.work / f"{how.name.lower()}-first"
        result = d.interrupted(row, d.run_args(run), "config.yaml", how)
        if result is None:
            return row
        if how == signal.SIGKILL:
            row.check(result.code == -signal.SIGKILL, "killed")
            row.check((run / LOCK_NAME).exists(), "stale run.lock left (expected after -9)")
        else:
            d.expect(row, result, 130, f"eslam resume {run}")
            row.check(not (run / LOCK_NAME).exists(), "lock released")
        row.check(not (run / "map.pt").exists(), "stopped before the first checkpoint")
        d.resumes(row, run)
        return row

    return drill


def _signal_after_checkpoint(how: signal.Signals) -> Callable[[Drills], Row]:
    def drill(d: Drills) -> Row:
        name = SIGNAL_NAMES[how]
        row = Row(f"{name} after a checkpoint, then resume")
        run = d.work / f"{how.name.lower()}-checkpoint"
        result = d.interrupted(row, d.run_args(run), "map.pt", how)
        if result is None:
            return row
        frames = d.saved_frames(run)
        if how == signal.SIGKILL:
            row.check(result.code == -signal.SIGKILL, "killed")
        else:
            d.expect(row, result, 130, "saved in", f"eslam resume {run}")
            row.check(not (run / LOCK_NAME).exists(), "lock released")
        row.check(0 < frames < FRAMES, f"{frames} frames saved", f"0 < frames saved < {FRAMES}")
        if how == signal.SIGKILL:  # checkpoints write map.pt, trajectory.txt, timings.json
            row.check((run / "map.pt").exists(), "map.pt of the last checkpoint kept")
        else:  # a stop also writes metrics.json of the frames so far
            metrics = json.loads((run / "metrics.json").read_text())
            row.check(metrics.get("frames") == frames, "metrics.json matches trajectory.txt")
        if how == signal.SIGINT:  # later drills start from this stopped run
            shutil.copytree(run, d.work / "sigint-checkpoint-stopped")
        d.resumes(row, run)
        return row

    return drill


def drill_unreadable_depth(d: Drills) -> Row:
    row = Row("unreadable depth PNG mid-sequence, then fix and resume")
    sequence = d.copy_sequence("seq-bad-depth")
    broken = d.depth_files(sequence)[4]
    good = broken.read_bytes()
    broken.write_bytes(b"not a png")
    run = d.work / "bad-depth"
    result = d.eslam(d.run_args(run, data=sequence))
    d.expect(row, result, 2, broken.name, f"eslam resume {run}")
    frames = d.saved_frames(run)
    row.check(frames == 4, f"the {frames} frames before it saved", "the 4 frames before it saved")
    broken.write_bytes(good)
    d.resumes(row, run)
    return row


def drill_odd_size(d: Drills) -> Row:
    row = Row("odd-sized colour frame mid-sequence, then fix and resume")
    sequence = d.copy_sequence("seq-odd-size")
    colour = sorted((sequence / "results").glob("frame*.jpg"))[4]
    good = colour.read_bytes()
    Image.open(colour).resize((40, 30)).save(colour, format="JPEG")
    run = d.work / "odd-size"
    result = d.eslam(d.run_args(run, data=sequence))
    d.expect(row, result, 2, colour.name, f"eslam resume {run}")
    frames = d.saved_frames(run)
    row.check(frames == 4, f"the {frames} frames before it saved", "the 4 frames before it saved")
    colour.write_bytes(good)
    d.resumes(row, run)
    return row


def drill_zero_depth(d: Drills) -> Row:
    row = Row("every depth frame all zero")
    sequence = d.copy_sequence("seq-zero-depth")
    d.rewrite_depth(sequence, lambda depth: depth * 0)
    run = d.work / "zero-depth"
    d.expect(row, d.eslam(d.run_args(run, data=sequence)), 2, "depth")
    row.check(not (run / "map.pt").exists(), "no map written from no depth")
    return row


def drill_zero_depth_one_frame(d: Drills) -> Row:
    row = Row("one depth frame all zero mid-sequence (sensor dropout)")
    sequence = d.copy_sequence("seq-zero-one")
    path = d.depth_files(sequence)[4]
    Image.fromarray(np.zeros_like(np.asarray(Image.open(path)))).save(path)
    run = d.work / "zero-one"
    result = d.eslam(d.run_args(run, data=sequence))
    if result.code == 0:
        d.expect(row, result, 0)
        row.check(d.saved_frames(run) == FRAMES, f"all {FRAMES} frames tracked")
    else:
        d.expect(row, result, 2, path.name)
    return row


def drill_depth_over_ten(d: Drills) -> Row:
    row = Row("depth PNGs divided by 10 (wrong units on disk)")
    sequence = d.copy_sequence("seq-depth-10")
    d.rewrite_depth(sequence, lambda depth: depth // 10)
    run = d.work / "depth-10"
    d.expect(row, d.eslam(d.run_args(run, data=sequence)), 2, "depth_scale")
    row.check(not (run / "map.pt").exists(), "no map written")
    return row


def drill_wrong_depth_scale(d: Drills) -> Row:
    row = Row("wrong data.depth_scale (1000 for Replica's 6553.5)")
    run = d.work / "depth-scale"
    d.expect(row, d.eslam(d.run_args(run, "data.depth_scale=1000")), 2, "depth_scale")
    row.check(not (run / "map.pt").exists(), "no map written")
    return row


def drill_grey16_colour(d: Drills) -> Row:
    row = Row("16-bit grey colour PNGs (plain folder layout)")
    sequence = d.work / "seq-grey16"
    config = SynthConfig(frames=FRAMES, width=80, height=60, seed=3)
    write_folder_sequence(sequence, generate_sequence(config), depth_scale=1000.0)
    for path in sorted((sequence / "color").glob("*.png")):
        grey = np.asarray(Image.open(path).convert("L")).astype(np.uint16) * 257
        Image.fromarray(grey).save(path)
    row.check(Image.open(path).mode.startswith("I"), "colour saved as 16-bit grey")
    run = d.work / "grey16"
    d.expect(row, d.eslam(d.run_args(run, "data.format=folder", data=sequence)), 0)
    row.check(d.saved_frames(run) == FRAMES, f"all {FRAMES} frames tracked")
    return row


def _bad_setting(case: str, setting: str) -> Callable[[Drills], Row]:
    """A bad ``key=value``: one line naming the key, exit 2, no run folder."""

    def drill(d: Drills) -> Row:
        row = Row(case)
        key = setting.split("=")[0]
        run = d.work / f"bad-{key}"
        d.expect(row, d.eslam(d.run_args(run, setting)), 2, key)
        d.nothing_written(row, run)
        return row

    return drill


def drill_format_option(d: Drills) -> Row:
    row = Row("`--format` given to eslam run")
    run = d.work / "format-option"
    d.expect(row, d.eslam([*d.run_args(run), "--format", "replica"]), 2, "data.format")
    d.nothing_written(row, run)
    return row


def drill_read_only(d: Drills) -> Row:
    row = Row("output folder on a read-only file system")
    with d.tmpfs("ro", "ro,size=1m") as where:
        if where is None:
            row.checks.append("mount refused here: covered by tests/test_output_errors.py")
            return row
        run = where / "run"
        d.expect(row, d.eslam(d.run_args(run)), 2, "read-only")
    return row


def drill_proc(d: Drills) -> Row:
    row = Row("`--out` under /proc")
    d.expect(row, d.eslam(d.run_args("/proc/eslam-drill")), 2, "/proc")
    return row


def drill_disk_full(d: Drills) -> Row:
    row = Row("disk full at the first checkpoint, then free space and resume")
    with d.tmpfs("full", "size=600k") as where:
        if where is None:
            row.checks.append(
                "mount refused here: covered by tests/test_output_errors.py "
                "(ENOSPC from torch.save simulated)"
            )
            return row
        run = where / "run"
        result = d.eslam(d.run_args(run))
        d.expect(row, result, 2, "map.pt", "free")
        row.check(not (run / LOCK_NAME).exists(), "lock released")
        leftovers = [p.name for p in run.iterdir() if p.name.startswith(".") or ".tmp" in p.name]
        row.check(not leftovers, "no temporary files left", f"no temporary files left: {leftovers}")
        subprocess.run(["mount", "-o", "remount,size=64m", str(where)], check=True)
        d.resumes(row, run)
    return row


def drill_second_run(d: Drills) -> Row:
    row = Row("second `eslam run --overwrite` into a live run's folder")
    run = d.work / "live"
    first = d.start(d.run_args(run))
    deadline = time.monotonic() + 300
    while not (run / LOCK_NAME).exists() and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    second = d.eslam([*d.run_args(run), "--overwrite"])
    d.expect(row, second, 2, "a run is still writing this folder")
    first.send_signal(signal.SIGTERM)
    _, err = first.communicate(timeout=300)
    row.check(first.returncode == 130, "first run stopped by SIGTERM: exit 130",
              f"first run exit 130 (got {first.returncode}: {err.strip()[-200:]!r})")  # fmt: skip
    d.resumes(row, run)
    return row


def drill_stale_lock(d: Drills) -> Row:
    row = Row("stale run.lock of a dead pid, then resume")
    run = d.interrupted_copy("stale-lock")
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock = {"pid": dead.pid, "host": socket.gethostname(), "started": time.time()}
    (run / LOCK_NAME).write_text(json.dumps(lock))
    row.command = "eslam resume $WORK/stale-lock  # run.lock names a dead pid"
    d.resumes(row, run)
    row.check("took over the lock" in (run / "log.txt").read_text(), "log.txt says lock taken over")
    return row


def drill_other_directory(d: Drills) -> Row:
    row = Row("run with relative paths, resume from another directory")
    args = d.run_args("rel-run", data="sequence")
    result = d.interrupted(row, args, "map.pt", signal.SIGINT, cwd=d.work)
    if result is None:
        return row
    d.expect(row, result, 130)
    elsewhere = d.work / "elsewhere"
    elsewhere.mkdir()
    row.command += "; then from $WORK/elsewhere: eslam resume ../rel-run"
    d.resumes(row, Path("..") / "rel-run", cwd=elsewhere)
    return row


def drill_moved_data(d: Drills) -> Row:
    row = Row("resume after the data moved, with `--data`")
    run = d.interrupted_copy("moved")
    moved = d.copy_sequence("seq-moved-tmp")
    original = d.work / "sequence-hidden"
    d.sequence.rename(original)  # the run's data.path no longer exists
    try:
        missing = d.eslam(["resume", str(run)])
        d.expect(row, missing, 2, "--data")
        row.command = f"{d.shown(['resume', str(run)])}; then with --data $WORK/seq-moved-tmp"
        d.resumes(row, run, "--data", str(moved))
        config = (run / "config.yaml").read_text()
        row.check(str(moved) in config, "config.yaml names the new place")
    finally:
        original.rename(d.sequence)
    return row


def _changed_sequence(grow: bool) -> Callable[[Drills], Row]:
    def drill(d: Drills) -> Row:
        row = Row(f"resume after the sequence {'grew' if grow else 'shrank'}")
        run = d.interrupted_copy(f"seq-{'grew' if grow else 'shrank'}")
        sequence = d.copy_sequence(f"seq-{'grown' if grow else 'shrunk'}")
        results = sequence / "results"
        traj = (sequence / "traj.txt").read_text().splitlines()
        if grow:
            shutil.copy(results / f"frame{FRAMES - 1:06d}.jpg", results / f"frame{FRAMES:06d}.jpg")
            shutil.copy(results / f"depth{FRAMES - 1:06d}.png", results / f"depth{FRAMES:06d}.png")
            traj.append(traj[-1])
        else:
            (results / f"frame{FRAMES - 1:06d}.jpg").unlink()
            (results / f"depth{FRAMES - 1:06d}.png").unlink()
            traj.pop()
        (sequence / "traj.txt").write_text("\n".join(traj) + "\n")
        before = d.snapshot(run)
        result = d.eslam(["resume", str(run), "--data", str(sequence)])
        d.expect(row, result, 2, "is not the input", "grew" if grow else "shrank")
        d.unchanged(row, run, before)
        return row

    return drill


def drill_eval_interrupted(d: Drills) -> Row:
    row = Row("`eslam eval` of a run interrupted after 4 frames")
    run = d.work / "eval-stopped"
    result = d.interrupted(row, d.run_args(run), "map.pt", signal.SIGINT, frames=4)
    if result is None:
        return row
    d.expect(row, result, 130)
    frames = d.saved_frames(run)
    scored = d.eslam(["eval", str(run)])
    row.command += f"; {d.shown(scored.args)}"
    row.code = scored.code
    d.expect(row, scored, 0)
    metrics = json.loads((run / "metrics.json").read_text())
    row.check(metrics.get("ate_frames") == frames and "ate_rmse_cm" in metrics,
              f"ATE over its {frames} frames")  # fmt: skip
    return row


def drill_eval_two_frames(d: Drills) -> Row:
    row = Row("`eslam eval` of a run interrupted after 2 frames (ATE needs 3)")
    run = d.interrupted_copy("eval-two")
    frames = d.saved_frames(run)
    if frames >= 3:
        row.checks.append(f"the stopped run kept {frames} frames: see the row above")
        return row
    before = d.snapshot(run)
    d.expect(row, d.eslam(["eval", str(run)]), 2, "needs at least 3", f"eslam resume {run}")
    d.unchanged(row, run, before)
    return row


def drill_eval_samples_zero(d: Drills) -> Row:
    row = Row("`eslam eval --samples 0`")
    run = d.work / "reference"
    before = d.snapshot(run)
    d.expect(row, d.eslam(["eval", str(run), "--samples", "0"]), 2, "--samples")
    d.unchanged(row, run, before)
    return row


def drill_resume_finished(d: Drills) -> Row:
    row = Row("resume a finished run keeps the eval keys")
    run = d.work / "finished"
    shutil.copytree(d.work / "reference", run)
    mesh = d.sequence / "mesh.ply"
    scored = d.eslam(
        ["eval", str(run), "--gt-mesh", str(mesh), "--samples", "2000", "--views", "0"]
    )
    if not row.check(scored.code == 0, "eval exit 0", f"eval exit 0 (got {scored.code})"):
        row.problems.append(scored.stderr.strip()[-300:])
        return row
    keys = set(json.loads((run / "metrics.json").read_text()))
    result = d.eslam(["resume", str(run)])
    row.command = f"eslam eval RUN --gt-mesh MESH; {d.shown(['resume', str(run)])}"
    d.expect(row, result, 0)
    after = json.loads((run / "metrics.json").read_text())
    lost = sorted(keys - set(after))
    row.check(not lost and "accuracy_cm" in after, "eval keys kept", f"eval keys kept: lost {lost}")
    d.same_as_reference(row, run)
    return row


DRILLS: list[tuple[str, Callable[[Drills], Row]]] = [
    ("sigint-first", _signal_first_frame(signal.SIGINT)),
    ("sigterm-first", _signal_first_frame(signal.SIGTERM)),
    ("kill9-first", _signal_first_frame(signal.SIGKILL)),
    ("sigint-checkpoint", _signal_after_checkpoint(signal.SIGINT)),
    ("sigterm-checkpoint", _signal_after_checkpoint(signal.SIGTERM)),
    ("kill9-checkpoint", _signal_after_checkpoint(signal.SIGKILL)),
    ("unreadable-depth", drill_unreadable_depth),
    ("odd-size", drill_odd_size),
    ("zero-depth", drill_zero_depth),
    ("zero-depth-one", drill_zero_depth_one_frame),
    ("depth-over-10", drill_depth_over_ten),
    ("depth-scale", drill_wrong_depth_scale),
    ("grey16", drill_grey16_colour),
    (
        "iterations",
        _bad_setting("`tracking.render.iterations=-1`", "tracking.render.iterations=-1"),
    ),
    ("rays", _bad_setting("`tracking.render.rays=0`", "tracking.render.rays=0")),
    ("crop", _bad_setting("`data.crop` larger than the image", "data.crop=100")),
    ("unknown-key", _bad_setting("unknown key `tracking.iters=5`", "tracking.iters=5")),
    ("format", drill_format_option),
    ("read-only", drill_read_only),
    ("proc", drill_proc),
    ("disk-full", drill_disk_full),
    ("second-run", drill_second_run),
    ("stale-lock", drill_stale_lock),
    ("other-dir", drill_other_directory),
    ("moved-data", drill_moved_data),
    ("grew", _changed_sequence(True)),
    ("shrank", _changed_sequence(False)),
    ("eval-stopped", drill_eval_interrupted),
    ("eval-two-frames", drill_eval_two_frames),
    ("eval-samples-0", drill_eval_samples_zero),
    ("resume-finished", drill_resume_finished),
]
"""(name for --only, drill), in table order; drills after sigint-checkpoint copy its
stopped run folder, so --only must keep it when it names those."""

NEEDS_STOPPED_RUN = {"stale-lock", "moved-data", "grew", "shrank", "eval-two-frames"}


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def table(rows: list[tuple[str, Row]]) -> str:
    """The markdown table of the drills' rows."""
    lines = [
        "| drill | case | command | exit | one line | checked afterwards | result |",
        "|---|---|---|---:|:---:|---|---|",
    ]
    for name, row in rows:
        one = {None: "", True: "yes", False: "**no**"}[row.one_line]
        code = "" if row.code is None else str(row.code)
        checked = "; ".join([*row.checks, *row.problems])
        verdict = "**FAIL**" if row.problems else "pass"
        lines.append(
            f"| {name} | {_cell(row.case)} | `{_cell(row.command)}` | {code} | {one} | "
            f"{_cell(checked)} | {verdict} |"
        )
    return "\n".join(lines) + "\n"


def replace_section(path: Path, section: str) -> None:
    """Put ``section`` (starting with HEADING) in ``path``: in place of the old one, or
    at the end (atomically)."""
    text = path.read_text(encoding="utf-8")
    start = text.find(f"\n{HEADING}\n")
    if start >= 0:
        end = text.find("\n## ", start + len(HEADING) + 2)
        tail = text[end:] if end >= 0 else ""
        text = text[:start].rstrip("\n") + "\n\n" + section.rstrip("\n") + "\n" + tail
    else:
        text = text.rstrip("\n") + "\n\n" + section.rstrip("\n") + "\n"
    write_text(path, text)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, help="folder for data and runs (default: temp)")
    parser.add_argument("--threads", type=int, default=1, help="threads= of every run (1)")
    parser.add_argument("--only", nargs="+", metavar="DRILL", help="run these drills only")
    parser.add_argument("--docs", type=Path, default=DEFAULT_DOCS, help="markdown file")
    parser.add_argument("--no-append", action="store_true", help="print the table only")
    parser.add_argument("--keep", action="store_true", help="keep the temporary work folder")
    args = parser.parse_args(argv)
    known = [name for name, _ in DRILLS]
    unknown = sorted(set(args.only or []) - set(known))
    if unknown:
        parser.error(f"unknown drills {unknown}; known: {' '.join(known)}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    command = command_line("benchmarks/failure_drills.py", argv)
    temporary = args.work is None
    work = Path(tempfile.mkdtemp(prefix="eslam-drills-")) if temporary else args.work.absolute()
    work.mkdir(parents=True, exist_ok=True)
    if any(work.iterdir()):
        print(f"--work {work}: must be empty", file=sys.stderr)
        return 2
    only = set(args.only or [name for name, _ in DRILLS])
    if only & NEEDS_STOPPED_RUN:
        only.add("sigint-checkpoint")
    drills = Drills(work, args.threads, lambda text: print(text, file=sys.stderr, flush=True))
    load_start = load_average()
    started = time.monotonic()
    rows: list[tuple[str, Row]] = []
    try:
        drills.setup()
        for name, drill in DRILLS:
            if name not in only:
                continue
            began = time.monotonic()
            try:
                row = drill(drills)
            except Exception as error:  # a drill that breaks is a failed drill, not a stop
                row = Row(name, problems=[f"the drill raised {type(error).__name__}: {error}"])
            rows.append((name, row))
            verdict = "FAIL" if row.problems else "pass"
            drills.show(f"{name}: {verdict} ({time.monotonic() - began:.0f} s) {row.problems}")
    finally:
        for mount in list(drills.mounts):
            subprocess.run(["umount", str(mount)], capture_output=True)
        if temporary and not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    failed = [name for name, row in rows if row.problems]
    import torch

    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    section = "\n".join(
        [
            HEADING,
            "",
            "Issue 15's cases, each run through the real `eslam` command by "
            "`benchmarks/failure_drills.py` on an 8-frame 80x60 synthetic sequence (tiny "
            "settings). A drill passes when the command succeeds or stops with exit 2 "
            "(130 for a signal) and one line on stderr, and the checks after it hold "
            "(saved frames intact, `eslam resume` ends on the uninterrupted run's "
            "trajectory). `$WORK` is the drills' work folder, `demo.yaml` is "
            "`eslam/configs/demo.yaml` and `$TINY` stands for the sequence's `scene.bound`, "
            "`threads=1` and the script's `TINY` settings.",
            "",
            f"{when}, {len(rows) - len(failed)} of {len(rows)} drills pass "
            f"({time.monotonic() - started:.0f} s):",
            "",
            *machine_lines(torch.device("cpu"), (load_start, load_average())),
            f"- command: `{command}`",
            "",
            table(rows),
        ]
    )
    print(section, end="")
    if not args.no_append:
        replace_section(args.docs, section)
        print(f"wrote the table to {args.docs}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
