"""Per-frame tracking-quality rows: which frames count as degenerate."""

from __future__ import annotations

from eslam.slam.state import degenerate_row, degenerate_stretch, quality_row
from eslam.slam.tracking.base import TrackingQuality

NAN = float("nan")


def row(failed: bool, directions: int | None) -> list[float]:
    return quality_row(TrackingQuality(5, 0.9, 0.002, failed, 0.001, directions))


def test_a_degenerate_frame_is_tracked_tested_and_not_failed() -> None:
    assert degenerate_row(row(False, 2))
    assert not degenerate_row(row(False, 0))  # tested, nothing open
    assert not degenerate_row(row(True, 6))  # failed: counted as failed, not degenerate
    assert not degenerate_row(row(False, None))  # the test was off
    assert not degenerate_row(quality_row(None))  # not judged at all
    assert not degenerate_row([5.0, 0.9, 0.002, 0.0, NAN, NAN])  # a map saved before the test


def test_the_stretch_is_the_trailing_run_of_degenerate_frames() -> None:
    rows = [row(False, 0), row(False, 3), row(True, 6), row(False, 1), row(False, 2)]
    assert degenerate_stretch(rows) == 2  # the failed frame ends the earlier stretch
    assert degenerate_stretch([*rows, row(False, 0)]) == 0
    assert degenerate_stretch([]) == 0
