"""Shared fixtures: real data location, deterministic torch threads."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# Idle OpenMP threads sleep instead of spinning: with any other load on a 2-core machine,
# spinning threads made the SLAM tests ~20x slower (206 s vs 12 s measured).
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# torch is imported after the OpenMP setting, which it reads at import.
import torch

from eslam.testing.tiny import TINY_SETTINGS

# Two threads per test, also when pytest-xdist runs two side by side (`pytest -n 2`,
# README): `eslam run` (the CLI, which tests call in-process) sets torch's threads to
# the config's `threads` (2) for the rest of the process, and a test comparing a run
# with another to 1e-7 needs both at the same count (float sums split by thread). At
# ESLAM_TEST_THREADS=1 the runs after a CLI test differ from those before by up to
# 6e-5 m (tests/slam/test_run_seams.py: the corrupt depth image, the interruption).
torch.set_num_threads(int(os.environ.get("ESLAM_TEST_THREADS", "2")))

# Without CUDA, plane_sampling: triton's tests run its kernels on CPU tensors in Triton's
# interpreter. Triton reads TRITON_INTERPRET as it decorates kernels, its own library
# ones (tl.sum's) at `import triton`, so it is set before anything imports triton (torch
# does not); it changes nothing else here (no other code uses triton on a CPU).
if not torch.cuda.is_available():
    os.environ.setdefault("TRITON_INTERPRET", "1")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Every test that skips without CUDA carries ``@pytest.mark.cuda`` too: the GPU
    check (benchmarks/gpu_check.py) runs ``pytest -m cuda`` and must not miss one."""
    unmarked = [
        item.nodeid
        for item in items
        if item.get_closest_marker("cuda") is None
        and any("CUDA" in str(m.kwargs.get("reason", "")) for m in item.iter_markers("skipif"))
    ]
    if unmarked:
        raise pytest.UsageError(
            "these tests skip without CUDA but lack @pytest.mark.cuda: " + ", ".join(unmarked)
        )


@pytest.fixture(scope="session")
def real_data() -> Path:
    """The folder of real sequences (../shared/data), from ESLAM_TEST_DATA; skip when unset."""
    location = os.environ.get("ESLAM_TEST_DATA")
    if not location:
        pytest.skip("ESLAM_TEST_DATA is not set (point it at the shared data folder)")
    path = Path(location)
    if not path.is_dir():
        pytest.fail(f"ESLAM_TEST_DATA={location} is not a folder")
    return path


@pytest.fixture
def register():
    """``register(registry, name, factory, **entry)``: add an entry for this test only."""
    added = []

    def add(registry, name: str, factory, **entry) -> None:
        registry.register(name, factory, **entry)
        added.append((registry, name))

    yield add
    for registry, name in reversed(added):
        registry.unregister(name)


TINY = list(TINY_SETTINGS)
"""Settings small enough for CI (2 cores): :data:`eslam.testing.tiny.TINY_SETTINGS`."""

TINY_FRAMES = 12
"""Frames of the shared tiny synthetic sequence (80x60, seed 3)."""


@pytest.fixture(scope="session")
def tiny_sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shared tiny synthetic sequence (Replica layout), written once per session."""
    from eslam.synthetic import SynthConfig, write_synthetic_sequence

    root = tmp_path_factory.mktemp("tiny") / "data"
    write_synthetic_sequence(root, SynthConfig(frames=TINY_FRAMES, width=80, height=60, seed=3))
    return root


def tiny_config(sequence: Path, *extra: str):
    """The demo config on ``sequence`` with its known bound and the TINY settings."""
    from eslam.config import load_config
    from eslam.synthetic import read_synthetic_bound
    from eslam.workflows.demo import DEMO_CONFIG

    bound = read_synthetic_bound(sequence)
    return load_config(
        DEMO_CONFIG, [f"data.path={sequence}", f"scene.bound={bound}", *TINY, *extra]
    )


def demo_config(sequence: Path, *extra: str):
    """The demo config (its CPU preset, whole) on the synthetic ``sequence`` with its
    known bound, no mesh and no progress bar."""
    from eslam.synthetic.runs import synthetic_run_config
    from eslam.workflows.demo import DEMO_CONFIG

    return synthetic_run_config(DEMO_CONFIG, sequence, *extra)


@pytest.fixture(scope="session")
def tiny_run(tiny_sequence: Path, tmp_path_factory: pytest.TempPathFactory):
    """One uninterrupted run on the tiny sequence (the reference other tests compare to)."""
    from eslam.slam.session import run_slam

    return run_slam(tiny_config(tiny_sequence), tmp_path_factory.mktemp("tiny_run") / "run")


def static_ate_cm(gt_poses) -> float:
    """ATE RMSE (cm) of a tracker that never moves: every pose = the first ground truth.

    Loop tests compare against it (a run must do much better), so a dead tracker fails.
    """
    import numpy as np

    from eslam.evaluate.trajectory import absolute_trajectory_error

    gt = np.asarray(gt_poses, dtype=np.float64)
    static = np.repeat(gt[:1], len(gt), axis=0)
    return 100.0 * absolute_trajectory_error(static, gt).rmse


@pytest.fixture(scope="session")
def tiny_static_ate_cm(tiny_sequence: Path) -> float:
    """:func:`static_ate_cm` of the tiny sequence (about 2.5 cm)."""
    from eslam.config import DataConfig
    from eslam.data import open_sequence

    return static_ate_cm(open_sequence(DataConfig(path=str(tiny_sequence))).gt_poses())


def close_after_adam(
    ours: torch.Tensor,
    reference: torch.Tensor,
    rtol: float,
    atol: float,
    outliers: float = 1e-4,
    largest: float = 1e-3,
) -> bool:
    """Parameters after Adam steps taken in two computation orders, equal up to rounding.

    Adam divides each element's gradient by its own running RMS, so an element whose
    gradient is rounding noise (near zero, its sign set by the order of a sum) can take
    a step of the learning rate's size in one order and not in the other: how many such
    elements there are depends on the CPU's vector width. All elements but a fraction
    ``outliers`` (at least one) must be allclose with ``rtol``/``atol``, and none may
    differ by more than ``largest`` (a learning-rate-sized step; a wrong gradient or a
    missed step moves far more elements than that).
    """
    difference = (ours - reference).abs()
    mismatched = ~torch.isclose(ours, reference, rtol=rtol, atol=atol)
    allowed = max(1, int(outliers * reference.numel()))
    return int(mismatched.sum()) <= allowed and float(difference.max()) <= largest
