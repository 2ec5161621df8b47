"""The cells of a sweep (:mod:`eslam.workflows.sweep`): planned from a sweep file with
their resolved configs and run folders, checked before anything runs, their status on
disk (cell.json) and whether each is finished. Running them is the sweep's backends'
job."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from eslam.config import ESLAMConfig, load_config
from eslam.config.packaged import find_config
from eslam.errors import ConfigError, ESLAMError, InputError
from eslam.io.run_dir import RunDirectory, json_text, write_json
from eslam.slam.session import resolve_config
from eslam.synthetic import read_synthetic_bound
from eslam.workflows.evaluate_run import EvaluationOptions
from eslam.workflows.sweep_file import SweepDataset, SweepFile, SweepVariant

CELL_FILE = "cell.json"
"""The status file of a cell (module docstring)."""


SWEEP_FILE = "sweep.json"
"""DIR/sweep.json: the grid of the last sweep into DIR (dataset, variant order for tables)."""


SYNTHETIC_MARKER = "synth.json"
"""A sequence folder holding it is a synthetic scene: its cells get its exact bound."""


@dataclass(frozen=True)
class Cell:
    """One run of a sweep.

    Attributes:
        dataset, variant, seed: where in the grid.
        config: the resolved configuration (``data.path`` absolute).
        run_dir: ``OUT/<dataset>/<variant>/seed<seed>``.
        evaluation: how the finished run is scored.
        paper_scene, paper_experiment: what of the paper it repeats (or None).
    """

    dataset: str
    variant: str
    seed: int
    config: ESLAMConfig
    run_dir: Path
    evaluation: EvaluationOptions
    paper_scene: str | None = None
    paper_experiment: str | None = None

    @property
    def name(self) -> str:
        """``dataset/variant/seed<k>``, the cell's folder under the sweep's output."""
        return f"{self.dataset}/{self.variant}/seed{self.seed}"


def plan_cells(sweep: SweepFile, out: str | Path, extra: Sequence[str] = ()) -> list[Cell]:
    """Every cell of ``sweep`` (``SweepFile.select`` picks datasets and variants), with
    its resolved configuration, in grid order (dataset, variant, seed); ``extra``
    overrides every cell last (``eslam sweep SWEEP key=value``, e.g. ``device=cuda``).

    Override order: ``threads`` (= resources.cpus), ``output.progress=false`` (the sweep
    draws one bar over cells), ``data.path``, the synthetic bound (module
    SYNTHETIC_MARKER), the sweep's overrides, the dataset's, the variant's, the
    dataset's for the variant (``variant_overrides``), ``extra``, ``seed``.

    Raises:
        ConfigError: a missing config, an invalid
            override or evaluation setting; the message names the sweep file and cell.
    """
    cells = []
    for dataset in sweep.datasets:
        evaluation = _evaluation_options(sweep, dataset)
        data = sweep.resolve(dataset.data, f"{dataset.name}.data").absolute()
        gt_mesh = (
            None
            if dataset.gt_mesh is None
            else sweep.resolve(dataset.gt_mesh, "gt_mesh").absolute()
        )
        for variant in sweep.variants:
            first = _cell_config(sweep, (dataset, variant), data, sweep.seeds[0], extra)
            for seed in sweep.seeds:
                config = dataclasses.replace(first, seed=seed)  # seed is the last override
                if gt_mesh is not None and not config.output.mesh:
                    raise ConfigError(
                        f"{sweep.path}: dataset {dataset.name!r} has a gt_mesh but variant "
                        f"{variant.name!r} sets output.mesh=false (no mesh to score): drop "
                        "one of them"
                    )
                cells.append(
                    Cell(
                        dataset.name,
                        variant.name,
                        seed,
                        config,
                        Path(out) / dataset.name / variant.name / f"seed{seed}",
                        dataclasses.replace(evaluation, gt_mesh=gt_mesh, device=config.device),
                        dataset.paper,
                        variant.paper,
                    )
                )
    return cells


def _evaluation_options(sweep: SweepFile, dataset: SweepDataset) -> EvaluationOptions:
    """The sweep's evaluation settings with the dataset's over them."""
    try:
        return EvaluationOptions(**{**dict(sweep.evaluation), **dict(dataset.evaluation)})
    except (ConfigError, TypeError) as error:
        raise ConfigError(f"{sweep.path}: evaluation of {dataset.name!r}: {error}") from None


def _config_file(sweep: SweepFile, text: str, key: str) -> Path:
    """A config's file: a path relative to the sweep file, else a packaged config."""
    path = sweep.resolve(text, key)
    if path.is_file():
        return path
    try:
        return find_config(text)
    except ConfigError:
        raise ConfigError(
            f"{sweep.path}: {key}: {text} is neither a file next to the sweep file nor a "
            "packaged config (`eslam configs` lists them)"
        ) from None


def _cell_config(
    sweep: SweepFile,
    where: tuple[SweepDataset, SweepVariant],
    data: Path,
    seed: int,
    extra: Sequence[str],
) -> ESLAMConfig:
    dataset, variant = where
    key = "base" if dataset.config is None else f"{dataset.name}.config"
    config_file = _config_file(sweep, dataset.config or sweep.base, key)
    bound = []
    if (data / SYNTHETIC_MARKER).is_file():
        bound = [f"scene.bound={read_synthetic_bound(data)}"]
    overrides = [
        f"threads={sweep.resources.cpus}",
        "output.progress=false",
        f"data.path={data}",
        *bound,
        *sweep.overrides,
        *dataset.overrides,
        *variant.overrides,
        *dataset.overrides_of(variant.name),
        *extra,
        f"seed={seed}",
    ]
    try:
        return resolve_config(load_config(config_file, overrides))
    except ConfigError as error:
        raise ConfigError(
            f"{sweep.path}: dataset {dataset.name!r}, variant {variant.name!r}: {error}"
        ) from None


def check_inputs(cells: Sequence[Cell]) -> None:
    """Refuse a sweep whose sequences or ground-truth meshes are missing, before any run.

    Raises:
        InputError: the first missing folder or file, named.
    """
    for path in dict.fromkeys(Path(str(cell.config.data.path)) for cell in cells):
        if not path.is_dir():
            raise InputError(
                path,
                "sequence folder not found",
                "fix the dataset's data in the sweep file, or the ${VARIABLE} it uses",
            )
    for mesh in dict.fromkeys(cell.evaluation.gt_mesh for cell in cells):
        if mesh is not None and not mesh.is_file():
            raise InputError(mesh, "ground-truth mesh not found", "fix the dataset's gt_mesh")


def is_finished(cell: Cell) -> bool:
    """True when the cell's folder holds its finished run of the same config, evaluated
    with the same settings."""
    return run_finished(cell) and read_status(cell.run_dir).get(
        "evaluation"
    ) == evaluation_settings(cell)


def run_finished(cell: Cell) -> bool:
    """True when the cell's run (not necessarily its evaluation) finished with its config."""
    run = RunDirectory(cell.run_dir)
    status = read_status(cell.run_dir)
    if status.get("run") != "done" or not run.metrics.is_file():
        return False
    return same_config(run, cell.config)


def evaluation_settings(cell: Cell) -> dict:
    """The cell's evaluation settings as cell.json records them."""
    return json.loads(json_text(dataclasses.asdict(cell.evaluation)))


def same_config(run: RunDirectory, config: ESLAMConfig) -> bool:
    if not run.config.is_file():
        return False
    try:
        return load_config(run.config) == config
    except ESLAMError:
        return False


def read_status(run_dir: Path) -> dict:
    try:
        status = json.loads((run_dir / CELL_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return status if isinstance(status, dict) else {}


def write_status(cell: Cell, status: str, **more: object) -> None:
    record = {
        "status": status,
        "dataset": cell.dataset,
        "variant": cell.variant,
        "seed": cell.seed,
        "paper_scene": cell.paper_scene,
        "paper_experiment": cell.paper_experiment,
        "error": None,
        **more,
    }
    write_json(cell.run_dir / CELL_FILE, record)


def describe_cells(cells: Sequence[Cell]) -> str:
    """The planned grid as JSON text (``eslam sweep --dry-run``)."""
    return json_text(
        [
            {
                "cell": cell.name,
                "data": cell.config.data.path,
                "finished": is_finished(cell),
                "gt_mesh": cell.evaluation.gt_mesh,
            }
            for cell in cells
        ]
    )
