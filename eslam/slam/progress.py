"""Progress display and resource figures of a run."""

from __future__ import annotations

import resource
import sys

import numpy as np
import torch

from eslam.evaluate.trajectory import absolute_trajectory_error

ATE_EVERY = 10
"""Frames between updates of the running ATE shown in the progress bar."""


class RunProgress:
    """A tqdm bar with frames/s and, when ground truth exists, the running ATE in cm."""

    def __init__(self, frames: int, start: int, enabled: bool, gt: np.ndarray | None) -> None:
        from tqdm import tqdm

        self.gt = gt
        self.bar = tqdm(
            total=frames, initial=start, unit="frame", disable=not enabled, file=sys.stderr
        )

    def update(self, index: int, poses: torch.Tensor) -> None:
        """Advance past frame ``index``; ``poses`` (index + 1, 4, 4) are the estimates so far."""
        self.bar.update(1)
        if self.gt is not None and index >= 2 and (index + 1) % ATE_EVERY == 0:
            estimated = poses.detach().cpu().double().numpy()
            gt = self.gt[: index + 1]
            usable = np.isfinite(estimated).all(axis=(1, 2)) & np.isfinite(gt).all(axis=(1, 2))
            if usable.sum() >= 3:
                ate = absolute_trajectory_error(estimated[usable], gt[usable])
                self.bar.set_postfix(ate_cm=f"{100 * ate.rmse:.2f}")

    def close(self) -> None:
        """Close the bar."""
        self.bar.close()


def peak_memory_mb(device: torch.device) -> float:
    """Peak memory of the run: CUDA allocator peak on a GPU, else the process's peak RSS."""
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
