"""A CPU stand-in for CUDA's sync debug mode: eslam code that reads a tensor's value on
the host (``bool``, ``int``, ``float``, ``.item()``, ``.tolist()``) or makes a shape
that depends on values (``.nonzero()``, ``.masked_select()``, indexing with a boolean
mask) raises inside :func:`no_host_reads`.

On a GPU each such read waits for the device; a step that makes none can be queued
ahead or captured in a CUDA graph. Only reads whose caller is eslam's own code trip the
wire: torch's optimisers read their CPU-side step counters, which never wait on a GPU.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path

import torch

import eslam

ESLAM_ROOT = str(Path(eslam.__file__).resolve().parent)
READS = (
    "__bool__",
    "__int__",
    "__float__",
    "__index__",
    "item",
    "tolist",
    "nonzero",
    "masked_select",
    "__getitem__",
)


def _is_read(name: str, args: tuple) -> bool:
    """Whether the call waits for the device: always, except indexing, which does only
    with a boolean mask (its result's shape depends on the values)."""
    if name != "__getitem__":
        return True
    index = args[0] if args else None
    parts = index if isinstance(index, tuple) else (index,)
    return any(isinstance(part, torch.Tensor) and part.dtype == torch.bool for part in parts)


class HostRead(AssertionError):
    """eslam code read a tensor's value on the host inside a step."""


@contextlib.contextmanager
def no_host_reads(count_only: bool = False) -> Iterator[list[str]]:
    """Inside, a host read of a tensor from eslam code raises :class:`HostRead` (with
    ``count_only``: is listed instead); yields the list of reads allowed through
    ("name file:line")."""
    originals = {name: getattr(torch.Tensor, name) for name in READS}
    others: list[str] = []

    def guard(name: str):
        original = originals[name]

        def read(self, *args, **kwargs):
            if not _is_read(name, args):
                return original(self, *args, **kwargs)
            caller = sys._getframe(1).f_code.co_filename
            where = f"{caller}:{sys._getframe(1).f_lineno}"
            ours = str(Path(caller).resolve()).startswith(ESLAM_ROOT)
            if ours and not count_only:
                raise HostRead(f"Tensor.{name} read on the host at {where}")
            others.append(f"{name} {where}" + (" (eslam)" if ours else ""))
            return original(self, *args, **kwargs)

        return read

    try:
        for name in READS:
            setattr(torch.Tensor, name, guard(name))
        yield others
    finally:
        for name, original in originals.items():
            setattr(torch.Tensor, name, original)
