"""README.md's set-up: what a user types, and the lines `.ci/run` takes from it."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
CI = (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def _ci_line(variable: str) -> str:
    """The README line .ci/run takes for ``variable`` (its ``readme_line 'REGEX'``)."""
    pattern = re.search(rf"^{variable}=\$\(readme_line '([^']*)'\)", CI, re.MULTILINE)
    assert pattern is not None, f".ci/run sets no {variable} from README.md"
    found = [line for line in README if re.match(pattern.group(1), line)]
    assert found, f"README.md has no line for {variable}"
    return found[0]


def _extras(line: str) -> set[str]:
    match = re.search(r'-e "\.\[([^]]*)\]"', line)
    assert match is not None, line
    return set(match.group(1).split(","))


def test_set_up_clones_and_enters_the_repository_before_installing() -> None:
    """The README began with `pip install -e .`, which only works inside a clone."""
    first_pip = next(i for i, line in enumerate(README) if line.startswith("pip install"))
    clone = next(i for i, line in enumerate(README) if line.startswith("git clone"))
    assert clone < first_pip and "&& cd " in README[clone]


def test_the_user_line_comes_first_without_developer_tools() -> None:
    """The one install line pulled pytest, ruff and import-linter into a user's venv."""
    user = next(line for line in README if line.startswith("pip install torch=="))
    assert "dev" not in _extras(user) and {"eval", "viz"} <= _extras(user)


def _declared_extras() -> set[str]:
    """pyproject.toml's extras (names under [project.optional-dependencies])."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    section = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    return set(re.findall(r"^(\w+) = \[", section, re.MULTILINE))


def test_ci_installs_every_extra_and_runs_the_readme_test_command() -> None:
    assert _extras(_ci_line("install_cmd")) == _declared_extras() >= {"eval", "viz", "dev"}
    assert _ci_line("test_cmd") == "pytest -n 2"  # two tests side by side (pytest-xdist)
