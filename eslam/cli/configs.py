"""``eslam configs``: list the packaged configs by the name ``eslam run`` takes."""

from __future__ import annotations

import argparse


def add(commands: argparse._SubParsersAction) -> None:
    """Add ``configs`` to ``commands``."""
    configs = commands.add_parser(
        "configs",
        help="list the packaged configs (names eslam run takes from any directory)",
        description=(
            "List the configs shipped with eslam (eslam/configs/), by the name `eslam run` "
            "takes as CONFIG from any directory, e.g. `eslam run replica/room0 --data PATH`; "
            "a path that exists is used as it is."
        ),
    )
    configs.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    """Print one line per packaged config: its name and summary."""
    from eslam.config.packaged import PACKAGED_CONFIGS, packaged_configs

    configs = packaged_configs()
    width = max(len(config.name) for config in configs)
    print(f"packaged configs (in {PACKAGED_CONFIGS}); pass a name as CONFIG to eslam run:")
    for config in configs:
        print(f"  {config.name:<{width}}  {config.summary}".rstrip())
    return 0
