"""Shared by the benchmark scripts: the machine description, the command line, and
appending a section to docs/benchmarks.md."""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from eslam.atomic import write_text
from eslam.config.device import resolve_device
from eslam.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DOCS = REPO / "docs" / "benchmarks.md"

INTRO = """# Benchmarks

Every figure here comes from a command in this repo; the machine is named with each
table. Sections are appended by the scripts in `benchmarks/` (see
`benchmarks/README.md`), newest last; the exact command line is given with each table
so it can be run again. Timings from different machines, thread counts or loads are
not comparable.
"""


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo, else what ``platform`` knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def load_average() -> float | None:
    """The 1-minute load average (None where the OS has none): other work on the machine."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else None


def machine_lines(device: torch.device, load: tuple[float | None, float | None]) -> list[str]:
    """Bullet lines naming the machine and software the timings were taken on."""
    lines = [
        f"- CPU: {cpu_model()}, {os.cpu_count()} logical cores; "
        f"{platform.system()} {platform.release()} ({platform.machine()})",
        f"- Python {platform.python_version()}, torch {torch.__version__}, "
        f"{torch.get_num_threads()} intra-op threads",
    ]
    if None not in load:
        lines.append(
            f"- 1-minute load average: {load[0]:.1f} at the start, {load[1]:.1f} at the end"
        )
    if device.type == "cuda":
        index = device.index if device.index is not None else torch.cuda.current_device()
        lines.append(f"- GPU: {torch.cuda.get_device_name(index)} (CUDA {torch.version.cuda})")
    return lines


def section_head(
    title: str,
    device: torch.device,
    load: tuple[float | None, float | None],
    command: str,
    data: str,
    overrides: tuple[str, list[str]] = ("overrides", []),
    note: str | None = None,
) -> list[str]:
    """A benchmark section's heading and bullets: ``## TITLE, UTC time, device``, the
    machine, the command, the data and, when given, the (label, list) overrides and a note."""
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## {title}, {now}, {device.type}",
        "",
        *machine_lines(device, load),
        f"- command: `{command}`",
        f"- data: {data}",
    ]
    label, given = overrides
    if given:
        lines.append(f"- {label}: `{' '.join(given)}`")
    if note:
        lines.append(f"- note: {note}")
    return lines


def append_section(path: Path, section: str) -> None:
    """Append ``section`` to the markdown file at ``path`` (created with the intro)."""
    text = path.read_text(encoding="utf-8") if path.exists() else INTRO
    write_text(path, text.rstrip("\n") + "\n\n" + section)


def add_device_argument(parser: argparse.ArgumentParser) -> None:
    """``--device``: any name the config's ``device`` takes; default auto."""
    parser.add_argument(
        "--device", default="auto", help="auto (CUDA, else MPS, else CPU), cpu, cuda:N, mps"
    )


def add_timing_arguments(parser: argparse.ArgumentParser, repeats: int, warmup: int) -> None:
    """The options every timing script shares: ``--device``, ``--repeats`` timed and
    ``--warmup`` untimed iterations (defaults given), ``--threads``, and where the
    section goes (``--docs``, ``--no-append``, ``--note``). Check them with
    :func:`check_timing_arguments`."""
    add_device_argument(parser)
    parser.add_argument("--repeats", type=int, default=repeats, help=f"timed ({repeats})")
    parser.add_argument("--warmup", type=int, default=warmup, help=f"untimed ({warmup})")
    parser.add_argument(
        "--threads", type=int, default=0, help="torch intra-op threads; 0 = torch's default"
    )
    parser.add_argument("--no-append", action="store_true", help="print only")
    parser.add_argument(
        "--docs", type=Path, default=DEFAULT_DOCS, help="markdown file to append to"
    )
    parser.add_argument("--note", default="", help="a remark printed with the machine")


def check_timing_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Stop with a usage error on counts out of range; resolve the device; apply
    ``--threads`` (torch's intra-op threads, when above 0)."""
    if args.repeats < 1 or args.warmup < 0 or args.threads < 0:
        parser.error("--repeats must be >= 1, --warmup and --threads >= 0")
    check_device(parser, args)
    if args.threads > 0:
        torch.set_num_threads(args.threads)


def check_device(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Resolve ``args.device`` in place (auto -> a concrete name), or stop with a usage error."""
    try:
        args.device = str(resolve_device(args.device))
    except ConfigError as error:
        parser.error(f"--device: {error}")


def publish(section: str, docs: Path, print_only: bool) -> None:
    """Print ``section`` and, unless ``print_only``, append it to ``docs``."""
    print(section, end="")
    if not print_only:
        append_section(docs, section)
        print(f"appended to {docs}")


def command_line(script: str, argv: list[str] | None) -> str:
    """The command that ran ``script`` (e.g. benchmarks/bench_core.py), path relative to
    the repo root; ``argv`` given = called from Python with those arguments."""
    if argv is not None:
        return shlex.join(["python", script, *argv])
    path = Path(sys.argv[0]).resolve()
    shown = path.relative_to(REPO).as_posix() if path.is_relative_to(REPO) else sys.argv[0]
    return shlex.join(["python", shown, *sys.argv[1:]])


def run_timing_benchmark(
    script: str,
    argv: list[str] | None,
    args: argparse.Namespace,
    run: Callable[[torch.device, int, int], Any],
    report: Callable[..., str],
) -> None:
    """The ``main`` of a timing benchmark: ``run(device, warmup, repeats)`` between two
    load-average readings, then ``report(results, device, args, command, loads)``
    printed and appended to ``args.docs`` (unless ``--no-append``)."""
    device = torch.device(args.device)
    command = command_line(script, argv)
    load_start = load_average()
    results = run(device, args.warmup, args.repeats)
    section = report(results, device, args, command, (load_start, load_average()))
    publish(section, args.docs, args.no_append)
