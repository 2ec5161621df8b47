"""The progress bar, as a run observer: frames/s and, with ground truth, the running ATE."""

from __future__ import annotations

import sys

import numpy as np

from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.slam.observers import FrameDone, RunEnd, RunObserverBase, RunStart

ATE_EVERY = 10
"""Frames between updates of the running ATE shown in the progress bar."""


def finite_ate_pairs(estimated: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(N,) bool: frames whose estimated and ground-truth poses are both finite.

    Frames without usable ground truth (NaN rows, e.g. ScanNet's lost tracking) are kept
    out of the ATE.
    """
    return np.isfinite(estimated).all(axis=(1, 2)) & np.isfinite(gt).all(axis=(1, 2))


class ProgressObserver(RunObserverBase):
    """A tqdm bar over the frames (total unknown for a live stream); does nothing when off."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bar = None
        self.state = None

    def on_start(self, start: RunStart) -> None:
        if not self.enabled:
            return
        from tqdm import tqdm

        done = start.state.next_frame
        total = None if start.frames is None else done + start.frames
        self.state = start.state
        self.bar = tqdm(total=total, initial=done, unit="frame", file=sys.stderr)

    def on_frame(self, frame: FrameDone) -> None:
        if self.bar is None or self.state is None:
            return
        self.bar.update(1)
        index = frame.index
        if index >= 2 and (index + 1) % ATE_EVERY == 0:
            trajectory = self.state.trajectory
            gt = trajectory.gt_poses()
            if gt is None:
                return
            estimated = trajectory.poses.detach().cpu().double().numpy()
            usable = finite_ate_pairs(estimated, gt)
            if usable.sum() >= 3:
                ate = absolute_trajectory_error(estimated[usable], gt[usable])
                self.bar.set_postfix(ate_cm=f"{100 * ate.rmse:.2f}")

    def _close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def on_finish(self, end: RunEnd) -> None:
        self._close()

    def on_failure(self, error: BaseException, frames: int) -> None:
        self._close()
