"""resolve_device: every place that takes a device name (config, --device) goes through it."""

from __future__ import annotations

import pytest
import torch

from eslam.config.device import resolve_device
from eslam.errors import ConfigError


def _accelerators(monkeypatch: pytest.MonkeyPatch, cuda: bool, mps: bool) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: cuda)
    monkeypatch.setattr(torch.backends.mps, "is_available", lambda: mps)


@pytest.mark.parametrize(
    ("cuda", "mps", "expected"),
    [(False, False, "cpu"), (True, False, "cuda"), (False, True, "mps"), (True, True, "cuda")],
)
def test_auto_picks_cuda_then_mps_then_cpu(monkeypatch, cuda, mps, expected) -> None:
    _accelerators(monkeypatch, cuda, mps)
    assert resolve_device("auto").type == expected


def test_explicit_names() -> None:
    assert resolve_device("cpu") == torch.device("cpu")
    if torch.cuda.is_available():
        assert resolve_device("cuda:0") == torch.device("cuda:0")


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("gpu", "unknown device 'gpu' (use auto, cpu, cuda, cuda:N or mps)"),
        ("cuda:99", "device 'cuda:99' asked for, but torch sees"),
    ],
)
def test_bad_names_are_config_errors(name: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        resolve_device(name)


def test_missing_accelerators_are_config_errors(monkeypatch) -> None:
    _accelerators(monkeypatch, cuda=False, mps=False)
    with pytest.raises(ConfigError, match="torch sees no MPS device"):
        resolve_device("mps")
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 0)
    with pytest.raises(ConfigError, match=r"torch sees 0 CUDA device\(s\)"):
        resolve_device("cuda")
