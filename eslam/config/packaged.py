"""The configs shipped inside the package (``eslam/configs/``), found by name.

``eslam run replica/room0`` works from any directory: a CONFIG that is no existing file
is looked up among the packaged configs, with or without ``.yaml`` and with or without
a leading ``configs/`` (so the README's ``configs/replica/room0.yaml`` works outside a
clone too). A path that exists always wins. ``eslam configs`` lists the names.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path

from eslam.errors import ConfigError

PACKAGED_CONFIGS = Path(__file__).resolve().parents[1] / "configs"
"""The folder of the packaged configs (``configs/`` in a clone links to it)."""

SUFFIX = ".yaml"


@dataclass(frozen=True)
class PackagedConfig:
    """One packaged config.

    Attributes:
        name: what to pass as CONFIG, e.g. ``replica/room0``.
        path: the file.
        summary: the first line of the file's leading comment ("" when it has none).
    """

    name: str
    path: Path
    summary: str


def packaged_configs() -> list[PackagedConfig]:
    """Every packaged config, sorted by name."""
    found = []
    for path in sorted(PACKAGED_CONFIGS.rglob(f"*{SUFFIX}")):
        name = path.relative_to(PACKAGED_CONFIGS).with_suffix("").as_posix()
        found.append(PackagedConfig(name, path, _summary(path)))
    return found


SUMMARY_WIDTH = 90
"""Longest summary ``eslam configs`` shows (characters)."""


def _summary(path: Path) -> str:
    """The first sentence of the file's leading comment block, at most SUMMARY_WIDTH long."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError:
        return ""
    comment = []
    for line in lines:
        if not line.startswith("#"):
            break
        comment.append(line.lstrip("#").strip())
    text = " ".join(comment)
    sentence = text.split(". ")[0].rstrip(".")
    if len(sentence) > SUMMARY_WIDTH:
        sentence = sentence[: SUMMARY_WIDTH - 3].rsplit(" ", 1)[0] + "..."
    return sentence


def find_config(config: str | Path) -> Path:
    """The file of ``config``: the path itself when it exists, else the packaged config of
    that name (``demo``, ``replica/room0``, ``replica/room0.yaml``, ``configs/cpu.yaml``).

    Raises:
        ConfigError: neither exists; the message gives the closest packaged name and
            says ``eslam configs`` lists them all.
    """
    path = Path(config)
    if path.is_file():
        return path
    name = path.as_posix()
    name = name.removeprefix("./").removeprefix("configs/")
    name = name.removesuffix(SUFFIX)
    candidate = PACKAGED_CONFIGS / f"{name}{SUFFIX}"
    if name and not path.is_absolute() and candidate.is_file():
        return candidate
    names = [c.name for c in packaged_configs()]
    close = difflib.get_close_matches(name, names, n=1)
    hint = f"did you mean '{close[0]}'? " if close else ""
    raise ConfigError(
        f"{config}: config file not found (give a path, or the name of a packaged config; "
        f"{hint}`eslam configs` lists them)"
    )
