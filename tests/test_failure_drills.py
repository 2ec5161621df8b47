"""benchmarks/failure_drills.py's own logic: what counts as a one-line stop, the table's
verdicts, and replacing its section of docs/reliability.md (the drills themselves run
whole CLI commands: minutes, so they are run by hand, not here)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def drills():
    sys.path.insert(0, str(BENCHMARKS))  # the script imports its sibling _machine
    try:
        spec = importlib.util.spec_from_file_location(
            "failure_drills", BENCHMARKS / "failure_drills.py"
        )
        module = importlib.util.module_from_spec(spec)
        sys.modules["failure_drills"] = module  # its dataclasses look their module up
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCHMARKS))
    return module


def test_a_stop_is_one_line_after_any_closed_progress_bars(drills) -> None:
    assert drills.stderr_is_one_line("eslam run: error: x.png: unreadable (fix it)\n")
    bars = "\rATE and plots:   0%|  | 0/1\rATE and plots: 100%|##| 1/1\n"
    assert drills.stderr_is_one_line(bars + "eslam eval: error: a (b)\n")
    assert not drills.stderr_is_one_line("")
    assert not drills.stderr_is_one_line("Traceback (most recent call last):\neslam: x\n")
    assert not drills.stderr_is_one_line("eslam run: error: a\neslam run: error: b\n")
    assert not drills.stderr_is_one_line("eslam run: error: a\n  more detail\n")


def test_a_drill_with_a_problem_is_a_fail_row(drills) -> None:
    good, bad = drills.Row("ok case", "eslam x", 0), drills.Row("bad case", "eslam y", 1)
    good.check(True, "exit 0")
    bad.check(False, "exit 2", "exit 2 (got 1)")
    text = drills.table([("good", good), ("bad", bad)])
    assert "| good | ok case | `eslam x` | 0 |  | exit 0 | pass |" in text
    assert "NOT exit 2 (got 1) | **FAIL** |" in text


def test_the_section_is_replaced_in_place_or_appended(drills, tmp_path: Path) -> None:
    docs = tmp_path / "reliability.md"
    docs.write_text("# R\n\nintro\n")
    drills.replace_section(docs, "## Failure drills\n\nfirst\n")
    assert docs.read_text() == "# R\n\nintro\n\n## Failure drills\n\nfirst\n"
    docs.write_text(docs.read_text() + "\n## Later\n\nkept\n")
    drills.replace_section(docs, "## Failure drills\n\nsecond\n")
    assert docs.read_text() == "# R\n\nintro\n\n## Failure drills\n\nsecond\n\n## Later\n\nkept\n"
