"""Turning a device name (config ``device``, ``--device``) into a usable torch device."""

from __future__ import annotations

import torch

from eslam.errors import ConfigError

AUTO = "auto"
"""The device name that picks the first accelerator torch sees (CUDA, then MPS), else CPU."""


def _accelerator() -> str | None:
    """The first accelerator torch can use here, or None."""
    if torch.cuda.is_available():
        return "cuda"
    mps = getattr(torch.backends, "mps", None)
    if mps is not None and mps.is_available():
        return "mps"
    return None


def resolve_device(name: str) -> torch.device:
    """The torch device for ``name``: cpu, cuda, cuda:N, mps, or auto.

    Raises:
        ConfigError: an unknown name, or an accelerator this machine's torch does not
            see (the message says which devices exist).
    """
    if name == AUTO:
        return torch.device(_accelerator() or "cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        raise ConfigError(f"unknown device '{name}' (use auto, cpu, cuda, cuda:N or mps)") from None
    if device.type == "cuda" and (device.index or 0) >= torch.cuda.device_count():
        raise ConfigError(
            f"device '{name}' asked for, but torch sees {torch.cuda.device_count()} CUDA "
            "device(s) (use cpu, auto or an existing cuda:N)"
        )
    if device.type == "mps" and _accelerator() != "mps":
        raise ConfigError(f"device '{name}' asked for, but torch sees no MPS device (use cpu)")
    return device
