"""Shared fixtures: real data location, deterministic torch threads."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
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
