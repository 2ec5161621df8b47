"""The GPU path in one short GPU run: CUDA tests, graph and core benchmarks, whole runs.

One command, sized for the device tool's lease (about 10 minutes of one command out of
15 minutes of device time, start-up included), prepared and smoke-tested on the CPU:

1. the CUDA-only tests (``pytest -m cuda``: CUDA graphs, the Triton kernel, the
   sync-debug checks of the steps, CUDA against CPU);
2. ``bench_graphs.py`` and ``bench_core.py`` on the device;
3. whole runs, each alone on the machine and each in a fresh process (so its first
   pose is a cold start): Replica room0 (20 frames) at the paper's settings and with
   the fast preset, 7-Scenes redkitchen and TUM fr1/xyz from frame 0 with the shipped
   presets, each with graphs and Triton off (``eager``) and on (``graphs+triton``). The
   first case also runs a second time in its process: the warm first pose.

It writes ``OUT/gpu_check.md``: the whole runs' table (frames per second over the whole
run, tracking and mapping milliseconds per iteration, first pose cold and warm, peak
memory, ATE, whether the graphs ran), then each step's output. The file is rewritten
after every step, so a run cut short still leaves what it measured. Steps that would not
fit in ``--budget-s`` are skipped with a line saying so; so is every CUDA-only part on
a machine without CUDA (the CPU smoke test: ``--device cpu --smoke``).

    python benchmarks/gpu_pack.py --out .gpu-data            # here: the frames to carry
    python benchmarks/gpu_check.py --data-root .gpu-data --out $OUT/gpu   # on the GPU
    python benchmarks/gpu_check.py --data-root ../shared/data --out /tmp/g --device cpu --smoke
"""

from __future__ import annotations

import time

PROCESS_START = time.perf_counter()  # before torch's import: a cold start counts it

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from dataclasses import asdict, dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import torch  # noqa: E402

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1])]
from _machine import REPO, add_device_argument, machine_lines  # noqa: E402
from gpu_runs import RUNS, VARIANTS, RunSpec, row_cells, run_one, table_head  # noqa: E402

from eslam.atomic import write_text  # noqa: E402
from eslam.config.device import resolve_device  # noqa: E402
from eslam.errors import ConfigError  # noqa: E402


@dataclass
class Report:
    """What the check measured so far, written to ``path`` after every step."""

    path: Path
    head: list[str]
    rows: list[str]
    sections: list[str]

    def write(self) -> None:
        table = [*table_head(), *self.rows] if self.rows else ["(no whole run finished)"]
        text = "\n".join([*self.head, "", "## Whole runs", "", *table, "", *self.sections])
        write_text(self.path, text.rstrip("\n") + "\n")

    def section(self, title: str, body: str) -> None:
        self.sections.append(f"## {title}\n\n{body.rstrip()}\n")
        self.write()


def cuda_test_files() -> list[str]:
    """The test files holding ``@pytest.mark.cuda`` tests (tests/conftest.py makes
    sure every test that skips without CUDA carries the mark)."""
    files = sorted((REPO / "tests").rglob("test_*.py"))
    return [str(f.relative_to(REPO)) for f in files if "mark.cuda" in f.read_text()]


def run_command(command: list[str], timeout_s: float, env: dict | None = None) -> str:
    """Run ``command`` from the repository root; its output (the tail, when long) with
    the exit status, or a line saying it ran past ``timeout_s``."""
    try:
        done = subprocess.run(
            command,
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            env={**os.environ, "PYTHONPATH": python_path(), **(env or {})},
        )
    except subprocess.TimeoutExpired:
        return f"stopped after {timeout_s:.0f} s (the step's share of --budget-s)"
    output = (done.stdout + done.stderr).strip()
    if len(output) > 6000:
        output = "...\n" + output[-6000:]
    return f"exit status {done.returncode}\n\n```\n{output}\n```"


def python_path() -> str:
    """PYTHONPATH for the steps: the repository first (the device machine runs the
    checkout without installing it), then what was set."""
    return os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)


class Budget:
    """Seconds left of ``total``; a step asks for its estimate before it starts."""

    def __init__(self, total: float) -> None:
        self.end = time.perf_counter() + total

    def left(self) -> float:
        return self.end - time.perf_counter()

    def allows(self, estimate_s: float) -> bool:
        return self.left() >= estimate_s


def benchmark_steps(args: argparse.Namespace) -> list[tuple[str, list[str], float]]:
    """(title, command, estimated seconds) of the benchmark scripts, sized by --smoke."""
    python = sys.executable
    smoke = ["--repeats", "2", "--warmup", "1"] if args.smoke else []
    graphs = [python, "benchmarks/bench_graphs.py", "--device", args.device, "--no-append"]
    core = [python, "benchmarks/bench_core.py", "--device", args.device, "--no-append"]
    if args.smoke:
        core += ["--benchmarks", "tracking", "--profile-repeats", "0", "--no-frame-work"]
    return [("bench_graphs.py", graphs + smoke, 60.0), ("bench_core.py", core + smoke, 90.0)]


def benchmark(
    step: tuple[str, list[str], float], report: Report, budget: Budget, cuda: bool
) -> None:
    """Run one benchmark script (title, command, estimated seconds) into the report."""
    title, command, estimate = step
    if "bench_graphs" in title and not cuda:
        report.section(title, "skipped: CUDA graphs need a CUDA device")
    elif budget.allows(estimate):
        report.section(title, run_command(command, min(budget.left(), 2 * estimate)))
    else:
        report.section(title, f"skipped: {budget.left():.0f} s left of --budget-s")


def whole_runs(
    specs: tuple[RunSpec, ...],
    args: argparse.Namespace,
    report: Report,
    budget: Budget,
    cuda: bool,
) -> list[str]:
    """Each run spec x variant in a fresh process: a table row per run; the lines
    saying which did not run, and why."""
    skipped = []
    for spec in specs:
        for variant in VARIANTS:
            label = f"{spec.name} {variant}"
            if VARIANTS[variant].needs_cuda and not cuda:
                skipped.append(f"- {label}: skipped, graphs and Triton need a CUDA device")
                continue
            frames = min(spec.frames, args.max_frames) if args.max_frames else spec.frames
            estimate = spec.estimate_s(frames, cuda)
            if not budget.allows(estimate):
                skipped.append(
                    f"- {label}: skipped, {budget.left():.0f} s left of --budget-s "
                    f"(needs about {estimate:.0f} s)"
                )
                continue
            row, why = run_in_child(spec, variant, frames, args, min(budget.left(), 3 * estimate))
            if row is None:
                skipped.append(f"- {label}: {why}")
            else:
                report.rows.append(row)
            report.write()
    return skipped


def run_in_child(
    spec: RunSpec, variant: str, frames: int, args: argparse.Namespace, timeout_s: float
) -> tuple[str | None, str]:
    """One whole run in a fresh process (``--one``): (its table row, "") or (None, why
    there is none)."""
    result = args.out / "runs" / f"{spec.name}-{variant}.json"
    result.unlink(missing_ok=True)
    command = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--one",
        spec.name,
        variant,
        "--frames",
        str(frames),
        "--data-root",
        str(args.data_root),
        "--out",
        str(args.out),
        "--device",
        args.device,
        "--threads",
        str(args.threads),
        *(["--smoke"] if args.smoke else []),
    ]
    status = run_command(command, timeout_s)
    if not result.is_file():
        return None, "no result: " + status
    return row_cells(json.loads(result.read_text())), ""


def check(args: argparse.Namespace) -> int:
    args.out.mkdir(parents=True, exist_ok=True)
    cuda = torch.device(args.device).type == "cuda" and torch.cuda.is_available()
    budget = Budget(args.budget_s)
    device = torch.device(args.device)
    head = [
        "# GPU check" + (" (CPU smoke test)" if args.smoke else ""),
        "",
        *machine_lines(device, (None, None)),
        f"- command: `python benchmarks/gpu_check.py {' '.join(sys.argv[1:])}`",
        f"- commit: {git_commit()}",
    ]
    report = Report(args.out / "gpu_check.md", head, [], [])
    report.write()
    files = cuda_test_files()
    if not cuda:
        report.section("CUDA tests", "skipped: no CUDA device (torch.cuda.is_available() is False)")
    elif budget.allows(60):
        command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "cuda"]
        report.section("CUDA tests", run_command([*command, *files], min(budget.left(), 240)))
    else:
        report.section("CUDA tests", f"skipped: {budget.left():.0f} s left of --budget-s")
    graphs, core = benchmark_steps(args)
    skipped = whole_runs(RUNS[:2], args, report, budget, cuda)  # the headline first
    benchmark(graphs, report, budget, cuda)
    skipped += whole_runs(RUNS[2:], args, report, budget, cuda)
    benchmark(core, report, budget, cuda)
    if skipped:
        report.section("Whole runs not in the table", "\n".join(skipped))
    print(report.path.read_text())
    return 0


def git_commit() -> str:
    try:
        done = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True
        )
    except OSError:
        return "unknown (no git)"
    return done.stdout.strip() or "unknown (not a git checkout)"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data-root", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    add_device_argument(parser)  # auto: CUDA where there is one
    parser.add_argument("--threads", type=int, default=4, help="torch CPU threads per run")
    parser.add_argument(
        "--budget-s", type=float, default=480.0, help="seconds for all steps (default 480)"
    )
    parser.add_argument("--max-frames", type=int, help="cap every whole run")
    parser.add_argument(
        "--smoke", action="store_true", help="CPU smoke test: 2 frames, tiny benchmarks"
    )
    parser.add_argument("--frames", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--one", nargs=2, metavar=("RUN", "VARIANT"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.smoke and args.max_frames is None:
        args.max_frames = 2
    if not args.data_root.is_dir():
        parser.exit(
            2,
            f"gpu_check.py: --data-root {args.data_root} is not a folder "
            "(make one with benchmarks/gpu_pack.py)\n",
        )
    try:
        args.device = str(resolve_device(args.device))
    except ConfigError as error:
        parser.exit(
            2, f"gpu_check.py: {error} (without CUDA, --device cpu --smoke runs the CPU parts)\n"
        )
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    if args.one:
        name, variant = args.one
        spec = next(r for r in RUNS if r.name == name)
        result = run_one(spec, variant, args.frames, args, PROCESS_START)
        path = args.out / "runs" / f"{name}-{variant}.json"
        write_text(path, json.dumps(asdict(result), indent=1))
        return 0
    return check(args)


if __name__ == "__main__":
    sys.exit(main())
