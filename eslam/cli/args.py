"""What every command's parser shares: the parser class, the exit status of a user
error, argument types and the settings list under ``eslam run --help``.

Nothing here imports torch or the library at import time (``import eslam.cli`` stays
light); :func:`settings_epilog` reads the config schema when called.
"""

from __future__ import annotations

import argparse
import textwrap
from typing import NoReturn

EXIT_USER_ERROR = 2
"""Exit status of a run stopped by bad input, bad configuration or a bad argument."""

EXIT_INTERRUPTED = 130
"""Exit status of a command stopped by Ctrl-C or SIGTERM (128 + SIGINT, as shells do)."""

SETTINGS_WIDTH = 100
"""Line width of the settings list under ``eslam run --help``."""


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block) naming the fix."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def image_size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` (e.g. 640x480) into (width, height)."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(part.isdigit() for part in parts):
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got '{text}'")
    width, height = int(parts[0]), int(parts[1])
    if width < 8 or height < 8:
        raise argparse.ArgumentTypeError(f"size must be at least 8x8, got '{text}'")
    return width, height


def _number(text: str, convert, accept, expected: str):
    """``convert(text)`` when ``accept`` holds for it, else the argparse error naming
    what was ``expected`` (nan is refused: it passes no comparison)."""
    try:
        value = convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got '{text}'") from None
    if not accept(value):
        raise argparse.ArgumentTypeError(f"expected {expected}, got '{text}'")
    return value


def positive_int(text: str) -> int:
    """Parse an integer > 0."""
    return _number(text, int, lambda value: value > 0, "a positive integer")


def non_negative_int(text: str) -> int:
    """Parse an integer >= 0."""
    return _number(text, int, lambda value: value >= 0, "an integer >= 0")


def positive_float(text: str) -> float:
    """Parse a number > 0 (not nan)."""
    return _number(text, float, lambda value: value > 0, "a positive number")


def non_negative_float(text: str) -> float:
    """Parse a number >= 0 (not nan)."""
    return _number(text, float, lambda value: value >= 0, "a number >= 0")


def settings_epilog() -> str:
    """Every config key as ``section.key (default): docstring``, read off the dataclasses.

    The text under ``eslam run --help``: built from :func:`eslam.config.config_help`
    (the field docstrings of :class:`eslam.config.ESLAMConfig`), never written by hand.
    """
    from eslam.config import config_help

    def fill(text: str, indent: str = "", more: str = "") -> str:
        return textwrap.fill(
            " ".join(text.split()),
            SETTINGS_WIDTH,
            initial_indent=indent,
            subsequent_indent=more,
            break_long_words=False,
            break_on_hyphens=False,
        )

    lines = [
        fill(
            "settings (key=value after CONFIG): key (default): what it does. The defaults "
            "are the schema's; CONFIG and the files it inherits from (configs/base.yaml) "
            "change some of them."
        )
    ]
    for row in config_help():
        lines.append(fill(f"{row.key} ({row.default}): {row.doc}", "  ", "      "))
    return "\n".join(lines)
