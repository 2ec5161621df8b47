"""The ``eslam`` command: thin wrappers over the Python API.

Every command is a function users can call from Python too; this package only parses
arguments, calls it and turns user errors into one line on stderr with exit status 2.
One module per command (``sweep`` and ``table`` share one), each with ``add(commands)``
adding its sub-parser and handler; :data:`COMMANDS` lists them in ``eslam --help``'s
order. Their heavy imports happen inside the handlers: importing this package imports
no torch.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from eslam import __version__
from eslam.cli import (
    ate,
    configs,
    demo,
    evaluate,
    inspect,
    mesh,
    recon,
    render,
    resume,
    run,
    sweep,
    synth,
)
from eslam.cli.args import (
    EXIT_INTERRUPTED,
    EXIT_USER_ERROR,
    SETTINGS_WIDTH,
    Parser,
    settings_epilog,
)
from eslam.cli.interrupts import stops_as_interrupt
from eslam.errors import ESLAMError, output_error

# Idle OpenMP threads sleep instead of spinning (set before anything imports torch): with
# other load on the machine, spinning threads slowed small CPU ops down ~20x here.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__all__ = [
    "COMMANDS",
    "EXIT_INTERRUPTED",
    "EXIT_USER_ERROR",
    "SETTINGS_WIDTH",
    "build_parser",
    "main",
    "settings_epilog",
]

COMMANDS = (synth, inspect, run, configs, resume, mesh, render, demo, evaluate, ate, recon, sweep)
"""The command modules, each with ``add(commands)``, in the order ``eslam --help`` lists
their commands (``sweep`` adds ``sweep`` and ``table``)."""


def build_parser() -> Parser:
    """The ``eslam`` argument parser with every sub-command."""
    parser = Parser(
        prog="eslam",
        description="ESLAM: dense neural RGB-D SLAM with multi-scale feature planes.",
    )
    parser.add_argument("--version", action="version", version=f"eslam {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    commands.required = True
    for command in COMMANDS:
        command.add(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``eslam`` console script; returns the exit status."""
    parser = build_parser()
    # key=value overrides may follow options (`run CONFIG --data X key=value`), which
    # argparse cannot match to a positional list once it has been consumed: collect them.
    args, extra = parser.parse_known_args(argv)
    if extra:
        overridable = hasattr(args, "overrides")
        bad = [item for item in extra if not overridable or item.startswith("-") or "=" not in item]
        given = list(sys.argv[1:] if argv is None else argv)
        options = [item for item in extra if item.startswith("--")]
        hint = _setting_hint(options, given) if overridable else None
        if hint is not None:
            print(
                f"eslam {args.command}: error: {hint} (see eslam {args.command} --help)",
                file=sys.stderr,
            )
            return EXIT_USER_ERROR
        if bad:
            parser.error(f"unrecognized arguments: {' '.join(bad)}")
        args.overrides = [*args.overrides, *extra]
    try:
        with stops_as_interrupt():
            return int(args.handler(args))
    except ESLAMError as error:
        print(f"eslam {args.command}: error: {error}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as error:
        # A write outside eslam.atomic (a folder created, log.txt opened): the same one
        # line as an atomic write's OutputError when the user can fix it, else a bug.
        mapped = output_error(error, error.filename) if error.filename else None
        if mapped is None:
            raise
        print(f"eslam {args.command}: error: {mapped}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt as interrupt:
        detail = str(interrupt) or "interrupted"
        if not detail.startswith("interrupted"):
            detail = f"interrupted: {detail}"
        print(f"eslam {args.command}: {detail}", file=sys.stderr)
        return EXIT_INTERRUPTED


def _setting_hint(unknown: Sequence[str], argv: Sequence[str]) -> str | None:
    """For an unknown option ``--name [VALUE]`` of ``argv`` that names a setting
    (``--format tum``), the message saying to pass it as ``key=VALUE`` after the config;
    None when none does."""
    from eslam.config import config_help

    for item in unknown:
        option, equals, value = item.partition("=")
        if not equals:
            position = list(argv).index(item)
            after = argv[position + 1] if position + 1 < len(argv) else ""
            value = after if after and not after.startswith("-") and "=" not in after else "VALUE"
        name = option[2:].replace("-", "_")
        keys = [row.key for row in config_help() if row.key.rsplit(".", 1)[-1] == name]
        if keys:
            settings = " or ".join(f"{key}={value}" for key in keys)
            return (
                f"{option} is no option here: settings follow the config as key=value, "
                f"e.g. {settings}"
            )
    return None
