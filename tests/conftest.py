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

torch.set_num_threads(int(os.environ.get("ESLAM_TEST_THREADS", "2")))


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
