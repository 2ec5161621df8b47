"""Resource figures of one run: device-aware wall clock and peak memory.

Both are per run, not per process, so two runs in one process (a notebook, a sweep)
report their own figures.
"""

from __future__ import annotations

import resource
import time
from pathlib import Path

import torch

_CLEAR_REFS = Path("/proc/self/clear_refs")
_STATUS = Path("/proc/self/status")


def device_clock(device: torch.device) -> float:
    """``time.perf_counter()`` after the device finished its queued work.

    On CUDA this waits for the device (once per call: call it at frame boundaries,
    never inside the optimisation steps), so the time includes the GPU work.
    """
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()


class PeakMemory:
    """Peak memory from :meth:`start` on: the CUDA allocator's peak on a GPU, else the
    process's peak resident set.

    On Linux the resident peak is reset at the start (``/proc/self/clear_refs``, value
    5), so it is the run's own; where that is not possible, the process's lifetime peak
    is reported and :attr:`per_run` is False.
    """

    def __init__(self, device: torch.device) -> None:
        self.device = device
        self.per_run = False

    def start(self) -> None:
        """Begin measuring (reset the peak)."""
        if self.device.type == "cuda":
            torch.cuda.reset_peak_memory_stats(self.device)
            self.per_run = True
            return
        try:
            _CLEAR_REFS.write_text("5")
            self.per_run = True
        except OSError:
            self.per_run = False

    def peak_mb(self) -> float:
        """The peak so far, MiB."""
        if self.device.type == "cuda":
            return torch.cuda.max_memory_allocated(self.device) / 2**20
        if self.per_run:
            for line in _STATUS.read_text().splitlines():
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
