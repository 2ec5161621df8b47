"""Sweep files: a grid of runs (datasets x variants x seeds) in one YAML file.

::

    base: demo                       # config every cell starts from (a packaged name
                                     # or a path relative to this file)
    datasets:
      - name: synth                  # the cells' folder OUT/synth/...
        data: ${ESLAM_SYNTH:-../out/demo/data}   # sets data.path
        config: replica/room0        # optional: replaces base for this dataset
        overrides: [data.max_frames=100]         # optional
        variant_overrides: {e: [render.samples_stratified=40]}  # optional, per variant
        gt_mesh: ${ESLAM_SYNTH:-../out/demo/data}/mesh.ply  # optional: mesh metrics
        paper: replica               # optional: the paper's scene to show beside ours
        evaluation: {depth_l1_views: 200}        # optional, over the sweep's evaluation
    seeds: [0, 1]                    # or a count: 5 = [0, 1, 2, 3, 4]
    variants:
      full: []
      h: {overrides: [mapping.optimise_poses=false], paper: h}
    overrides: [output.mesh=false]   # optional, every cell
    resources: {cpus: 1, gpus: 0}    # per cell: Ray's num_cpus / num_gpus; cpus = threads
    evaluation: {samples: 450000, depth_l1_views: 1000}   # optional, eslam eval's options

Paths (``base``, ``config``, ``data``, ``gt_mesh``) expand ``${NAME}`` and
``${NAME:-default}`` from the environment, then a relative path is taken from the
sweep file's folder (a ``base`` / ``config`` that is no file there is a packaged
config's name). A variant is a list of ``key=value`` overrides, or a mapping with
``overrides`` and ``paper`` (the paper's experiment it repeats, for ``eslam table``:
:mod:`eslam.workflows.paper_values`). Every problem is one :class:`ConfigError` line
naming the sweep file and the key. docs/sweeps.md documents the format.

Over 400 lines on purpose: the sweep-file format and all its checks, so every problem
is reported with its file and key from one place.
"""

from __future__ import annotations

import dataclasses
import difflib
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from eslam.errors import ConfigError
from eslam.workflows.paper_values import PAPER_EXPERIMENTS, PAPER_SCENES

TOP_KEYS = ("base", "datasets", "seeds", "variants", "overrides", "resources", "evaluation")
DATASET_KEYS = (
    *("name", "data", "config", "overrides", "variant_overrides"),
    *("gt_mesh", "paper", "evaluation"),
)
VARIANT_KEYS = ("overrides", "paper")
RESOURCE_KEYS = ("cpus", "gpus")
EVALUATION_KEYS = (
    "protocol",
    "samples",
    "exact",
    "depth_l1_views",
    "seed",
    "cull_every",
    "max_unobserved_fraction",
)
"""Settings of ``evaluation`` (the fields of EvaluationOptions that ``eslam eval`` takes)."""

NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")
"""Dataset and variant names: they become folder names."""
VARIABLE_PATTERN = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")
"""``${NAME}`` or ``${NAME:-default}`` in a path."""


@dataclass(frozen=True)
class Resources:
    """What one cell asks for.

    Attributes:
        cpus: CPU cores (Ray's ``num_cpus``), also the cell's torch threads
            (``threads=cpus`` before the sweep's own overrides).
        gpus: GPUs (Ray's ``num_gpus``; fractions share one); the local backend ignores it.
    """

    cpus: int = 1
    gpus: float = 0.0


@dataclass(frozen=True)
class SweepDataset:
    """One dataset of a sweep.

    Attributes:
        name: folder name of its cells.
        data: the sequence folder as written (``${...}`` not yet expanded).
        config: its config (replaces the sweep's base), as written; None = base.
        overrides: ``key=value`` for its cells (after the sweep's).
        variant_overrides: more ``key=value`` for some variants on this dataset (after
            the variant's), by variant name: e.g. the sample count of "all samples
            stratified" depends on the dataset's config.
        gt_mesh: ground-truth mesh as written; None = no mesh metrics.
        paper: the paper's scene its cells are compared with (``replica``,
            ``replica/room0``, ``scannet``); None = none.
        evaluation: ``eslam eval`` settings of its cells (over the sweep's).
    """

    name: str
    data: str
    config: str | None = None
    overrides: tuple[str, ...] = ()
    variant_overrides: tuple[tuple[str, tuple[str, ...]], ...] = ()
    gt_mesh: str | None = None
    paper: str | None = None
    evaluation: tuple[tuple[str, Any], ...] = ()

    def overrides_of(self, variant: str) -> tuple[str, ...]:
        """This dataset's extra overrides for ``variant`` (none when it has none)."""
        return dict(self.variant_overrides).get(variant, ())


@dataclass(frozen=True)
class SweepVariant:
    """One variant: overrides of every cell, and the paper's experiment it repeats.

    Attributes:
        name: folder name of its cells.
        overrides: ``key=value`` (after the dataset's).
        paper: the paper's experiment (``full``, ``a`` ... ``h``, ``x2``, ``x10``,
            ``depth/8``); None = none.
    """

    name: str
    overrides: tuple[str, ...] = ()
    paper: str | None = None


@dataclass(frozen=True)
class SweepFile:
    """A parsed, checked sweep file (module docstring).

    Attributes:
        path: the file.
        base: config every cell starts from, as written.
        datasets: in file order.
        seeds: the seeds of every dataset and variant.
        variants: in file order.
        overrides: ``key=value`` of every cell (before the dataset's).
        resources: per cell.
        evaluation: ``eslam eval`` settings (EVALUATION_KEYS) of every cell.
    """

    path: Path
    base: str
    datasets: tuple[SweepDataset, ...]
    seeds: tuple[int, ...]
    variants: tuple[SweepVariant, ...]
    overrides: tuple[str, ...] = ()
    resources: Resources = Resources()
    evaluation: tuple[tuple[str, Any], ...] = ()

    def select(self, datasets: Sequence[str] = (), variants: Sequence[str] = ()) -> SweepFile:
        """This sweep with only the named datasets and variants (all where none are named).

        Raises:
            ConfigError: a name the sweep file does not have.
        """
        chosen = {}
        for kind, names, entries in (
            ("dataset", datasets, self.datasets),
            ("variant", variants, self.variants),
        ):
            have = [entry.name for entry in entries]
            unknown = [name for name in names if name not in have]
            if unknown:
                raise ConfigError(
                    f"{self.path}: no {kind} named {unknown[0]!r} (it has: {', '.join(have)})"
                )
            chosen[kind] = tuple(e for e in entries if not names or e.name in names)
        return dataclasses.replace(self, datasets=chosen["dataset"], variants=chosen["variant"])

    def resolve(self, text: str, key: str) -> Path:
        """The path ``text`` of ``key``: ``${...}`` expanded, relative to the file's folder."""
        return resolve_path(text, self.path, key)


def load_sweep(path: str | Path) -> SweepFile:
    """Read and check the sweep file at ``path``.

    Raises:
        ConfigError: unreadable YAML, an unknown or missing key, a value of the wrong
            kind; one line naming the file and the key.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: sweep file not found")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise ConfigError(f"{path}: not a readable YAML file ({first})") from None
    problem = _Problems(path)
    if not isinstance(data, Mapping):
        raise problem.at("", "must be a mapping with base, datasets, seeds and variants")
    problem.unknown(data, TOP_KEYS, "")
    for key in ("base", "datasets", "seeds", "variants"):
        if key not in data:
            raise problem.at(key, "is missing (docs/sweeps.md shows the format)")
    base = problem.text(data["base"], "base")
    datasets = _datasets(data["datasets"], problem)
    variants = _variants(data["variants"], problem)
    names = [variant.name for variant in variants]
    for index, dataset in enumerate(datasets):
        for name, _ in dataset.variant_overrides:
            if name not in names:
                raise problem.at(
                    f"datasets[{index}].variant_overrides.{name}",
                    f"no such variant (variants: {', '.join(names)})",
                )
    return SweepFile(
        path=path,
        base=base,
        datasets=datasets,
        seeds=_seeds(data["seeds"], problem),
        variants=variants,
        overrides=problem.overrides(data.get("overrides", []), "overrides"),
        resources=_resources(data.get("resources", {}), problem),
        evaluation=_evaluation(data.get("evaluation", {}), problem),
    )


def resolve_path(text: str, sweep_path: Path, key: str) -> Path:
    """``text`` with ``${NAME}`` / ``${NAME:-default}`` taken from the environment, ``~``
    expanded, a relative result joined to ``sweep_path``'s folder; made absolute.

    Raises:
        ConfigError: a ``${NAME}`` without default whose variable is not set.
    """

    def value(match: re.Match) -> str:
        name, default = match.group(1), match.group(2)
        found = os.environ.get(name)
        if found:
            return found
        if default is not None:
            return default
        raise ConfigError(
            f"{sweep_path}: {key}: ${{{name}}} is not set "
            f"(export {name}=PATH, or write ${{{name}:-DEFAULT}} in the file)"
        )

    expanded = os.path.expanduser(VARIABLE_PATTERN.sub(value, text))
    return Path(os.path.abspath(os.path.join(sweep_path.parent, expanded)))


class _Problems:
    """Builds the one-line errors of one sweep file."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def at(self, key: str, problem: str) -> ConfigError:
        where = f"{key}: " if key else ""
        return ConfigError(f"{self.path}: {where}{problem}")

    def unknown(self, data: Mapping, valid: tuple[str, ...], prefix: str) -> None:
        for key in data:
            if key not in valid:
                close = difflib.get_close_matches(str(key), valid, n=1)
                hint = f"did you mean '{close[0]}'? " if close else ""
                raise self.at(f"{prefix}{key}", f"unknown key ({hint}valid: {', '.join(valid)})")

    def text(self, value: object, key: str) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.at(key, f"must be a text (a path or a config name), got {value!r}")
        return value

    def choice(self, value: object, key: str, choices: tuple[str, ...]) -> str | None:
        if value is None:
            return None
        if value not in choices:
            raise self.at(key, f"must be one of {', '.join(choices)}, got {value!r}")
        return str(value)

    def name(self, value: object, key: str) -> str:
        if not isinstance(value, str) or not NAME_PATTERN.fullmatch(value):
            raise self.at(
                key, f"must be a folder-safe name (letters, digits, _ . + -), got {value!r}"
            )
        return value

    def overrides(self, value: object, key: str) -> tuple[str, ...]:
        if value is None:
            return ()
        if not isinstance(value, list) or not all(
            isinstance(item, str) and "=" in item for item in value
        ):
            raise self.at(key, f"must be a list of key=value overrides, got {value!r}")
        return tuple(value)


def _datasets(value: object, problem: _Problems) -> tuple[SweepDataset, ...]:
    if not isinstance(value, list) or not value:
        raise problem.at("datasets", "must be a non-empty list of {name, data, ...}")
    datasets: list[SweepDataset] = []
    for index, entry in enumerate(value):
        key = f"datasets[{index}]"
        if not isinstance(entry, Mapping):
            raise problem.at(key, f"must be a mapping with name and data, got {entry!r}")
        problem.unknown(entry, DATASET_KEYS, f"{key}.")
        for required in ("name", "data"):
            if required not in entry:
                raise problem.at(f"{key}.{required}", "is missing")
        name = problem.name(entry["name"], f"{key}.name")
        if any(dataset.name == name for dataset in datasets):
            raise problem.at(f"{key}.name", f"'{name}' is used twice (names are folders)")
        optional = {
            field: problem.text(entry[field], f"{key}.{field}")
            for field in ("config", "gt_mesh")
            if entry.get(field) is not None
        }
        optional["paper"] = problem.choice(entry.get("paper"), f"{key}.paper", PAPER_SCENES)
        datasets.append(
            SweepDataset(
                name=name,
                data=problem.text(entry["data"], f"{key}.data"),
                overrides=problem.overrides(entry.get("overrides", []), f"{key}.overrides"),
                variant_overrides=_variant_overrides(entry, key, problem),
                evaluation=_evaluation(entry.get("evaluation", {}), problem, f"{key}.evaluation"),
                **optional,
            )
        )
    return tuple(datasets)


def _variant_overrides(
    entry: Mapping, key: str, problem: _Problems
) -> tuple[tuple[str, tuple[str, ...]], ...]:
    value = entry.get("variant_overrides", {})
    if not isinstance(value, Mapping):
        raise problem.at(
            f"{key}.variant_overrides", f"must map variant names to overrides, got {value!r}"
        )
    return tuple(
        (str(name), problem.overrides(items, f"{key}.variant_overrides.{name}"))
        for name, items in value.items()
    )


def _seeds(value: object, problem: _Problems) -> tuple[int, ...]:
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 1:
            raise problem.at("seeds", f"a count of seeds must be >= 1, got {value}")
        return tuple(range(value))
    if (
        not isinstance(value, list)
        or not value
        or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in value)
    ):
        raise problem.at("seeds", f"must be a count or a list of integers >= 0, got {value!r}")
    if len(set(value)) != len(value):
        raise problem.at("seeds", f"lists a seed twice: {value}")
    return tuple(value)


def _variants(value: object, problem: _Problems) -> tuple[SweepVariant, ...]:
    if not isinstance(value, Mapping) or not value:
        raise problem.at("variants", "must be a mapping of name: [key=value, ...]")
    variants = []
    for name, entry in value.items():
        key = f"variants.{name}"
        problem.name(name, key)
        if isinstance(entry, Mapping):
            problem.unknown(entry, VARIANT_KEYS, f"{key}.")
            variants.append(
                SweepVariant(
                    name,
                    problem.overrides(entry.get("overrides", []), f"{key}.overrides"),
                    problem.choice(entry.get("paper"), f"{key}.paper", PAPER_EXPERIMENTS),
                )
            )
        else:
            variants.append(SweepVariant(name, problem.overrides(entry, key)))
    return tuple(variants)


def _resources(value: object, problem: _Problems) -> Resources:
    if not isinstance(value, Mapping):
        raise problem.at("resources", f"must be a mapping like {{cpus: 1, gpus: 0}}, got {value!r}")
    problem.unknown(value, RESOURCE_KEYS, "resources.")
    cpus = value.get("cpus", 1)
    gpus = value.get("gpus", 0)
    if not isinstance(cpus, int) or isinstance(cpus, bool) or cpus < 1:
        raise problem.at("resources.cpus", f"must be an integer >= 1, got {cpus!r}")
    if not isinstance(gpus, (int, float)) or isinstance(gpus, bool) or gpus < 0:
        raise problem.at("resources.gpus", f"must be a number >= 0, got {gpus!r}")
    return Resources(cpus, float(gpus))


def _evaluation(
    value: object, problem: _Problems, key: str = "evaluation"
) -> tuple[tuple[str, Any], ...]:
    if not isinstance(value, Mapping):
        raise problem.at(key, f"must be a mapping of eslam eval settings, got {value!r}")
    problem.unknown(value, EVALUATION_KEYS, f"{key}.")
    return tuple(value.items())
