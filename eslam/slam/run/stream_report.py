"""What a real-time run reports about its stream: frames received, processed, dropped.

:func:`stream_metrics` gives metrics.json's keys (the run writer adds them);
:class:`StreamLog` writes the same figures to the run's log when the run ends and
warns once when the first frame is dropped, so a user sees early that the system is
slower than the stream. The progress bar shows the dropped count as it grows.
"""

from __future__ import annotations

import logging

import numpy as np

from eslam.data.realtime import LatestFrameReader, StreamCounts
from eslam.slam.run.observers import FrameDone, RunEnd, RunObserverBase


def stream_metrics(counts: StreamCounts, processed: int, lags_s: list[float]) -> dict:
    """metrics.json's real-time keys: frames received from the stream, dropped (received
    but not processed: replaced by a newer frame while the system was busy, or still
    waiting when the run ended), and the stream's rate; ``processed`` frames were done.
    With ``lags_s`` (per processed frame, seconds from its arrival to its pose): the
    tracker's lag behind the camera, mean and largest."""
    metrics = {
        "frames_received": counts.received,
        "frames_dropped": counts.received - processed,
        "received_fps": counts.received_fps,
    }
    if lags_s:
        metrics["tracking_lag_s_mean"] = float(np.mean(lags_s))
        metrics["tracking_lag_s_max"] = float(np.max(lags_s))
    return metrics


class StreamLog(RunObserverBase):
    """The real-time stream's figures in the run's log (module doc).

    Args:
        stream: the run's real-time reader.
        logger: the run's log.
    """

    def __init__(self, stream: LatestFrameReader, logger: logging.Logger) -> None:
        self.stream = stream
        self.log = logger
        self._warned = False

    def on_frame(self, frame: FrameDone) -> None:
        if self._warned:
            return
        replaced = self.stream.counts().replaced
        if replaced > 0:
            self._warned = True
            self.log.warning(
                "real time: the system is slower than the stream; frames are dropped "
                "(%d by frame %d), the newest is processed",
                replaced,
                frame.index,
            )

    def on_finish(self, end: RunEnd) -> None:
        self._report(end.frames)

    def on_failure(self, error: BaseException, frames: int) -> None:
        self._report(frames)

    def _report(self, processed: int) -> None:
        counts = self.stream.counts()
        rate = processed / counts.wall_s if counts.wall_s > 0 else 0.0
        self.log.info(
            "real time: %d frames received (%.1f fps), %d processed (%.1f fps), %d dropped",
            counts.received,
            counts.received_fps,
            processed,
            rate,
            counts.received - processed,
        )
