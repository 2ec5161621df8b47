"""`eslam sweep SWEEP.yaml --out DIR`: every cell of a sweep file run and evaluated.

A cell is one (dataset, variant, seed) of the grid (:mod:`eslam.workflows.sweep_file`;
planned, checked and its status kept by :mod:`eslam.workflows.sweep_cells`):
its run folder ``DIR/<dataset>/<variant>/seed<k>/`` holds the usual run outputs
(config.yaml fully resolved, trajectory, metrics.json ...), the evaluation of
``eslam eval`` (metrics.json's ATE and, with a ground-truth mesh, the mesh metrics;
report.md) and cell.json, the cell's status::

    {"status": "running" | "done" | "failed" | "interrupted", "error": one line or null,
     "run": "done" once the run finished (its evaluation may still fail), "evaluation":
     the evaluation settings of a done cell, "seconds": ..., "dataset": ..., "variant":
     ..., "seed": ..., "paper_scene": ..., "paper_experiment": ...}

Backends (:data:`SWEEP_BACKENDS`, a :class:`~eslam.registry.Registry`): ``local`` runs
cells one after another in this process (``jobs`` = 1) or in ``jobs`` spawned worker
processes; ``ray`` submits each cell as a Ray task asking for the sweep's ``resources``
(Ray, the ``[cluster]`` extra, is imported only here).
Each cell's torch thread count is its ``threads`` setting (``resources.cpus`` unless
overridden), set in the process that runs it.

Resuming: a cell whose cell.json says done and whose config.yaml is the cell's
resolved config is skipped, unless its evaluation settings changed (then only the
evaluation runs again); one whose run stopped part way (same config, a map.pt)
continues with ``eslam resume``'s logic; any other is run afresh. A failed cell records
its one-line error (and the traceback of a bug) in cell.json and the sweep goes on.
Ctrl-C stops the running cells as ``eslam run`` does (completed frames saved); finished
cells are untouched.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from eslam.errors import ConfigError, ESLAMError
from eslam.io.run_dir import RunDirectory, write_json
from eslam.registry import Registry
from eslam.slam.session import run_slam
from eslam.workflows.evaluate_run import evaluate_run
from eslam.workflows.sweep_cells import (
    CELL_FILE,
    SWEEP_FILE,
    Cell,
    check_inputs,
    evaluation_settings,
    is_finished,
    plan_cells,
    read_status,
    run_finished,
    same_config,
    write_status,
)
from eslam.workflows.sweep_file import SweepFile


@dataclass(frozen=True)
class CellOutcome:
    """What running a cell did.

    Attributes:
        cell: the cell's name.
        status: ``done``, ``failed``, ``skipped`` (finished before) or ``interrupted``.
        error: the one-line error of a failed cell.
        seconds: wall time of the run and its evaluation.
    """

    cell: str
    status: str
    error: str | None = None
    seconds: float = 0.0


@dataclass(frozen=True)
class SweepSummary:
    """The outcome of every cell of a sweep, in grid order."""

    out: Path
    outcomes: tuple[CellOutcome, ...]

    def count(self, status: str) -> int:
        """Cells with ``status``."""
        return sum(outcome.status == status for outcome in self.outcomes)

    @property
    def failed(self) -> tuple[CellOutcome, ...]:
        """The failed cells."""
        return tuple(outcome for outcome in self.outcomes if outcome.status == "failed")

    def text(self) -> str:
        """One summary line."""
        failed = self.failed
        line = (
            f"sweep {self.out}: {len(self.outcomes)} cells, {self.count('done')} run, "
            f"{self.count('skipped')} finished before, {len(failed)} failed"
        )
        if failed:
            line += f" (errors in {failed[0].cell}/{CELL_FILE} ...; rerun to retry them)"
        return line


@contextlib.contextmanager
def cell_threads(threads: int) -> Iterator[None]:
    """torch's CPU threads set to ``threads`` (0 = unchanged) inside, restored after."""
    import torch

    previous = torch.get_num_threads()
    if threads > 0:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def one_line(error: BaseException) -> str:
    """An error as one line: an ESLAMError's own message, else ``Type: first line``."""
    text = str(error).strip()
    first = text.splitlines()[0] if text else ""
    if isinstance(error, ESLAMError):
        return first
    return f"{type(error).__name__}: {first}" if first else type(error).__name__


def run_cell(cell: Cell) -> CellOutcome:
    """Run and evaluate ``cell`` (skipped when finished before); record cell.json.

    Errors are recorded, not raised (the sweep goes on); Ctrl-C is recorded as
    ``interrupted`` and raised again.
    """
    if is_finished(cell):
        return CellOutcome(cell.name, "skipped")
    started = time.monotonic()
    run = RunDirectory(cell.run_dir)
    ran = run_finished(cell)  # only the evaluation settings changed: evaluate again
    resume = not ran and run.map.is_file() and same_config(run, cell.config)
    cell.run_dir.mkdir(parents=True, exist_ok=True)
    write_status(cell, "running", run="done" if ran else None)
    try:
        with cell_threads(cell.config.threads):
            if not ran:
                run_slam(cell.config, cell.run_dir, resume=resume, overwrite=not resume)
                write_status(cell, "running", run="done")
            evaluate_run(cell.run_dir, cell.evaluation)
    except KeyboardInterrupt:
        run_state = read_status(cell.run_dir).get("run")
        write_status(cell, "interrupted", run=run_state, seconds=time.monotonic() - started)
        raise
    except Exception as error:
        seconds = time.monotonic() - started
        trace = None if isinstance(error, ESLAMError) else traceback.format_exc()
        run_state = read_status(cell.run_dir).get("run")
        write_status(
            cell, "failed", run=run_state, error=one_line(error), traceback=trace, seconds=seconds
        )
        return CellOutcome(cell.name, "failed", one_line(error), seconds)
    seconds = time.monotonic() - started
    write_status(cell, "done", run="done", evaluation=evaluation_settings(cell), seconds=seconds)
    return CellOutcome(cell.name, "done", None, seconds)


def _run_cell_in_worker(cell: Cell) -> CellOutcome:
    """:func:`run_cell` in a worker process: Ctrl-C there is an outcome, not an error
    (the driver stops the sweep)."""
    try:
        return run_cell(cell)
    except KeyboardInterrupt:
        return CellOutcome(cell.name, "interrupted")


Report = Callable[[CellOutcome], None]

RunCells = Callable[[Sequence[Cell], SweepFile, int, str | None, Report], None]
"""A sweep backend: ``run(cells, sweep, jobs, address, record)`` runs ``cells`` and calls
``record(outcome)`` as each one finishes (module docstring)."""

SWEEP_BACKENDS: Registry[None] = Registry("sweep backend", "backend")
"""The ways to run a sweep's cells, by the name ``run_sweep(backend=...)`` (``eslam sweep
--backend``) takes. An entry's factory is a :data:`RunCells`: it runs the cells (it
returns nothing). Built in: ``local`` and ``ray`` (registered below their functions)."""


def run_sweep(
    sweep: SweepFile,
    out: str | Path,
    backend: str = "local",
    jobs: int = 1,
    address: str | None = None,
    progress: bool = True,
    extra: Sequence[str] = (),
) -> SweepSummary:
    """Run every cell of ``sweep`` into ``out`` (module docstring).

    Args:
        sweep: the parsed sweep file.
        out: the output folder (with Ray on several machines: a folder every node reaches
            at the same path).
        backend: a name of :data:`SWEEP_BACKENDS` (``local`` or ``ray``).
        jobs: local backend: cells at a time (worker processes when > 1).
        address: ray backend: the cluster to join (``auto``, ``host:6379``); None starts
            a local one (or uses the one this process already initialised).
        progress: a bar over cells on stderr.
        extra: ``key=value`` overrides of every cell, applied last (before the seed).

    Raises:
        ConfigError, InputError: an unknown backend, a bad sweep file or missing input,
            before any cell runs.
        KeyboardInterrupt: Ctrl-C, after the running cells saved their frames.
    """
    run_cells: RunCells = SWEEP_BACKENDS.entry(backend).factory
    if jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {jobs}")
    out = Path(out)
    cells = plan_cells(sweep, out, extra)
    check_inputs(cells)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / SWEEP_FILE, _grid(sweep, cells))
    outcomes: dict[str, CellOutcome] = {}
    pending = []
    for cell in cells:
        if is_finished(cell):
            outcomes[cell.name] = CellOutcome(cell.name, "skipped")
        else:
            pending.append(cell)
    with _progress_bar(len(cells), len(outcomes), progress) as report:

        def record(outcome: CellOutcome) -> None:
            outcomes[outcome.cell] = outcome
            report(outcome)

        try:
            run_cells(pending, sweep, jobs, address, record)
        except KeyboardInterrupt:
            finished = sum(o.status in ("done", "skipped") for o in outcomes.values())
            raise KeyboardInterrupt(
                f"interrupted: {finished} of {len(cells)} cells finished and kept, running "
                f"cells saved their frames; run the same eslam sweep command to continue"
            ) from None
    return SweepSummary(out, tuple(outcomes[cell.name] for cell in cells))


def _grid(sweep: SweepFile, cells: Sequence[Cell]) -> dict:
    return {
        "sweep_file": str(sweep.path.absolute()),
        "datasets": list(dict.fromkeys(cell.dataset for cell in cells)),
        "variants": [variant.name for variant in sweep.variants],
        "seeds": list(sweep.seeds),
        "resources": dataclasses.asdict(sweep.resources),
    }


@contextlib.contextmanager
def _progress_bar(total: int, done: int, enabled: bool) -> Iterator[Report]:
    """A tqdm bar over cells (ETA from the cells run so far); yields ``report(outcome)``."""
    if not enabled:
        yield lambda outcome: None
        return
    from tqdm import tqdm

    failed = 0
    with tqdm(total=total, initial=done, desc="sweep", unit="cell") as bar:

        def report(outcome: CellOutcome) -> None:
            nonlocal failed
            failed += outcome.status == "failed"
            bar.set_postfix_str(f"last {outcome.cell}: {outcome.status}, {failed} failed")
            if outcome.status != "interrupted":
                bar.update(1)

        yield report


def _stop_if_interrupted(outcome: CellOutcome) -> None:
    if outcome.status == "interrupted":
        raise KeyboardInterrupt(f"interrupted: cell {outcome.cell} stopped (its frames saved)")


def _run_locally(
    cells: Sequence[Cell], sweep: SweepFile, jobs: int, address: str | None, record: Report
) -> None:
    """The ``local`` backend: cells one after another in this process (``jobs`` = 1), else
    in ``jobs`` worker processes (``address`` is Ray's, unused)."""
    if jobs == 1:
        for cell in cells:
            record(run_cell(cell))
    else:
        _run_in_processes(cells, jobs, record)


def _run_in_processes(cells: Sequence[Cell], jobs: int, record: Report) -> None:
    """Cells in ``jobs`` spawned worker processes (each sets its own torch threads)."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    context = multiprocessing.get_context("spawn")
    executor = ProcessPoolExecutor(max_workers=jobs, mp_context=context)
    try:
        running = {executor.submit(_run_cell_in_worker, cell): cell for cell in cells}
        while running:
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                cell = running.pop(future)
                try:
                    outcome = future.result()
                except Exception as error:  # the worker process died (killed, out of memory)
                    outcome = worker_lost(cell, error)
                record(outcome)
                _stop_if_interrupted(outcome)
    except KeyboardInterrupt:
        executor.shutdown(wait=True, cancel_futures=True)  # running cells save their frames
        raise
    executor.shutdown(wait=True)


def worker_lost(cell: Cell, error: BaseException) -> CellOutcome:
    """Record ``cell`` as failed when the process running it died without an outcome."""
    message = f"the worker process running the cell died ({one_line(error)})"
    write_status(cell, "failed", error=message)
    return CellOutcome(cell.name, "failed", message)


def _ray_module():
    try:
        import ray
    except ImportError:
        raise ConfigError(
            '--backend ray needs Ray: pip install "eslam[cluster]" (or use --backend local)'
        ) from None
    return ray


def _run_on_ray(
    cells: Sequence[Cell], sweep: SweepFile, jobs: int, address: str | None, record: Report
) -> None:
    """The ``ray`` backend: each cell a Ray task asking for the sweep's resources (Ray
    schedules them; ``jobs`` is the local backend's, unused)."""
    ray = _ray_module()
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=address or "local")
        except (ConnectionError, RuntimeError, ValueError) as error:
            raise ConfigError(
                f"--address {address or 'local'}: cannot start or join the Ray cluster "
                f"({one_line(error)}); see docs/sweeps.md"
            ) from None
    try:
        _check_cluster(ray.cluster_resources(), sweep)
        resources = sweep.resources
        task = ray.remote(num_cpus=resources.cpus, num_gpus=resources.gpus, max_retries=1)(
            _run_cell_in_worker
        )
        refs = {task.remote(cell): cell for cell in cells}
        running = list(refs)
        try:
            while running:
                finished, running = ray.wait(running, num_returns=1)
                try:
                    outcome = ray.get(finished[0])
                except Exception as error:  # the task's worker died after its retry
                    outcome = worker_lost(refs[finished[0]], error)
                record(outcome)
                _stop_if_interrupted(outcome)
        except KeyboardInterrupt:
            for ref in running:
                ray.cancel(ref)  # a KeyboardInterrupt in the task: its frames are saved
            with contextlib.suppress(Exception):
                ray.wait(running, num_returns=len(running), timeout=60)
            raise
    finally:
        if started:
            ray.shutdown()


SWEEP_BACKENDS.register("local", _run_locally)
SWEEP_BACKENDS.register("ray", _run_on_ray)


def _check_cluster(available: dict, sweep: SweepFile) -> None:
    """Refuse resources no node offers (such tasks would wait forever).

    Raises:
        ConfigError: more CPUs or GPUs per cell than the cluster has.
    """
    resources = sweep.resources
    for name, asked in (("CPU", resources.cpus), ("GPU", resources.gpus)):
        have = float(available.get(name, 0.0))
        if asked > have:
            raise ConfigError(
                f"{sweep.path}: resources.{name.lower()}s: each cell asks for {asked:g} {name}s "
                f"but the Ray cluster has {have:g}: lower it (gpus: 0 on machines without "
                "GPUs) or join a cluster that has them (--address)"
            )
