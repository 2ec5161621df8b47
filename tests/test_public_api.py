"""The package's public API: four names, imported on first use, so `import eslam` stays light."""

from __future__ import annotations

import subprocess
import sys

import pytest

import eslam


def test_importing_eslam_imports_neither_torch_nor_the_library() -> None:
    code = (
        "import sys, eslam; "
        "print(sorted(m for m in ('torch', 'numpy', 'eslam.slam', 'eslam.data') "
        "if m in sys.modules))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert result.stdout.strip() == "[]"


def test_public_names_come_from_their_modules() -> None:
    from eslam.config import load_config
    from eslam.data import open_sequence
    from eslam.io.saved_run import load_run
    from eslam.slam.session import run_slam

    assert eslam.__all__ == ["load_config", "load_run", "open_sequence", "run_slam"]
    assert eslam.load_config is load_config
    assert eslam.load_run is load_run
    assert eslam.open_sequence is open_sequence
    assert eslam.run_slam is run_slam
    assert set(eslam.__all__) <= set(dir(eslam))


def test_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="module 'eslam' has no attribute 'track'"):
        eslam.track  # noqa: B018
