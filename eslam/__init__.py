"""eslam: dense neural RGB-D SLAM (ESLAM, CVPR 2023) on CPU and GPU.

The public API, imported on first use (a module ``__getattr__``, PEP 562), so nothing
runs on import and ``import eslam`` does not import torch:

- ``run_slam(config, out_dir)``: run on a sequence, write a run folder (eslam.slam.session);
- ``load_config(path, overrides)``: a checked, fully resolved config (eslam.config);
- ``open_sequence(config.data)``: the frames of a dataset folder (eslam.data);
- ``load_run(run_dir)``: a run folder read back (eslam.io.saved_run).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from eslam.config import load_config
    from eslam.data import open_sequence
    from eslam.io.saved_run import load_run
    from eslam.slam.session import run_slam

__version__ = "0.1.0"

_HOMES = {
    "load_config": "eslam.config",
    "load_run": "eslam.io.saved_run",
    "open_sequence": "eslam.data",
    "run_slam": "eslam.slam.session",
}
"""The module each public name is imported from on first use."""

__all__ = ["load_config", "load_run", "open_sequence", "run_slam"]


def __getattr__(name: str) -> object:
    if name not in _HOMES:
        raise AttributeError(f"module 'eslam' has no attribute '{name}'")
    return getattr(importlib.import_module(_HOMES[name]), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
