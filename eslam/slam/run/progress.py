"""The progress bar, as a run observer: frames/s and, with ground truth, the running ATE.

The first frame of a process is unlike the rest (the map's first mapping call runs
``mapping.first_iterations``, minutes on a CPU, and the first steps compile and warm
caches), so it gets a bar of its own over those mapping iterations, and the frames
bar's rate and ETA count from the end of that frame: a 5-minute run no longer starts
by promising 2 hours. The bars are closed before the run's error or "interrupted"
line is printed, so that line stands on its own under them.
"""

from __future__ import annotations

import sys
from typing import TextIO

import numpy as np

from eslam.data.realtime import LatestFrameReader
from eslam.evaluate.trajectory import absolute_trajectory_error
from eslam.slam.mapping.concurrent_mapping import COMPONENT as CONCURRENT
from eslam.slam.run.observers import FrameDone, MappingStep, RunEnd, RunObserverBase, RunStart
from eslam.slam.state import failed_stretch

ATE_EVERY = 10
"""Frames between updates of the running ATE shown in the progress bar."""


def finite_ate_pairs(estimated: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(N,) bool: frames whose estimated and ground-truth poses are both finite.

    Frames without usable ground truth (NaN rows, e.g. ScanNet's lost tracking) are kept
    out of the ATE.
    """
    return np.isfinite(estimated).all(axis=(1, 2)) & np.isfinite(gt).all(axis=(1, 2))


class ProgressObserver(RunObserverBase):
    """A tqdm bar over the frames (total unknown for a live stream) and one over the first
    mapping call's iterations; does nothing when off, not even reading the device
    (module doc). A real-time run's bar also shows the frames dropped so far and how far
    behind the camera the last pose came (seconds), a concurrent run's the keyframes
    being mapped or waiting.

    Args:
        enabled: draw the bars.
        file: where to draw them (default: stderr, looked up when the run starts).
        stream: the real-time reader of a real-time run.
    """

    def __init__(
        self,
        enabled: bool,
        file: TextIO | None = None,
        stream: LatestFrameReader | None = None,
    ) -> None:
        self.enabled = enabled
        self.file = file
        self.stream = stream
        self.postfix: dict[str, str] = {}
        self.bar = None
        self.mapping_bar = None
        self.state = None
        self._clock_restarted = False

    def on_start(self, start: RunStart) -> None:
        if not self.enabled:
            return
        from tqdm import tqdm

        done = start.state.next_frame
        # real time: how many frames will be processed (not dropped) is unknown
        unknown = start.frames is None or self.stream is not None
        total = None if unknown else done + start.frames
        self.state = start.state
        self.bar = tqdm(total=total, initial=done, unit="frame", file=self._file())

    def _file(self) -> TextIO:
        return self.file if self.file is not None else sys.stderr

    def on_mapping_step(self, step: MappingStep) -> None:
        """The first mapping call's iterations on a second bar, closed when it is done."""
        if self.bar is None or not step.first:
            return
        if self.mapping_bar is None and step.done < step.iterations:
            from tqdm import tqdm

            self.mapping_bar = tqdm(
                total=step.iterations,
                desc=f"mapping frame {step.index} (the map's first call)",
                unit="it",
                leave=False,
                file=self._file(),
            )
        if self.mapping_bar is not None:
            self.mapping_bar.update(step.done - self.mapping_bar.n)
            if step.done >= step.iterations:
                self._close_mapping()

    def on_frame(self, frame: FrameDone) -> None:
        if self.bar is None or self.state is None:
            return
        self._close_mapping()
        if self._clock_restarted:
            self.bar.update(1)
        else:  # the process's first frame: counted, but not in the rate
            restart_clock(self.bar, self.bar.n + 1)
            self._clock_restarted = True
        postfix = dict(self.postfix)
        if self.stream is not None:
            postfix["dropped"] = str(self.stream.counts().replaced)
            postfix["lag_s"] = f"{self.stream.age_s(frame.index):.1f}"  # behind the camera
        concurrent = self.state.components.get(CONCURRENT)
        if concurrent is not None:  # keyframes mapping or waiting beside the tracker
            postfix["map_queue"] = str(concurrent.get("queue", 0))
        lost = failed_stretch(self.state.tracking_quality)
        if lost:
            postfix["lost_frames"] = str(lost)  # the camera is lost: failed frames in a row
        else:
            postfix.pop("lost_frames", None)
        index = frame.index
        if index >= 2 and (index + 1) % ATE_EVERY == 0:
            ate_cm = self._ate_cm()
            if ate_cm is not None:
                postfix["ate_cm"] = ate_cm
        if postfix != self.postfix:
            self.postfix = postfix
            self.bar.set_postfix(postfix)

    def _ate_cm(self) -> str | None:
        """The running ATE, shown in cm; None without ground truth for 3 frames."""
        if self.state is None:
            return None
        trajectory = self.state.trajectory
        gt = trajectory.gt_poses()
        if gt is None:
            return None
        estimated = trajectory.poses.detach().cpu().double().numpy()
        usable = finite_ate_pairs(estimated, gt)
        if usable.sum() < 3:
            return None
        ate = absolute_trajectory_error(estimated[usable], gt[usable])
        return f"{100 * ate.rmse:.2f}"

    def _close_mapping(self) -> None:
        if self.mapping_bar is not None:
            self.mapping_bar.close()
            self.mapping_bar = None

    def close(self) -> None:
        """Close the bars (again is fine): the run loop does so however the run ends."""
        self._close_mapping()
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def on_finish(self, end: RunEnd) -> None:
        self.close()

    def on_failure(self, error: BaseException, frames: int) -> None:
        self.close()


def restart_clock(bar, done: int) -> None:
    """Show ``done`` on the tqdm ``bar`` and count its rate and ETA from now, with
    ``done`` as the starting count (``reset`` clears the clock and the smoothed rate)."""
    bar.reset(total=bar.total)
    bar.initial = bar.n = bar.last_print_n = done
    bar.refresh()
