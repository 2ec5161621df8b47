"""A run's per-frame tracking quality, summarised by frame ranges.

Reads ``RUN/timings.json`` (written by every run whose tracker judges itself: `sdf`,
`hybrid`) and prints, per range of frames, the smallest normalised information
(``tracking_information``: minimum, median, maximum), the frames with a degenerate
direction (``tracking_degenerate_directions`` > 0) and the median tracking time per
frame (``tracking_s``). No SLAM runs here; the figures are the run's own.

    python benchmarks/tracking_quality.py RUN --bounds 1 83 100 240   # [1, 83), [83, 100), ...
    python benchmarks/tracking_quality.py RUN --every 25               # 25-frame ranges from 0
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class RangeQuality:
    """The tracking quality of frames ``start`` to ``stop - 1`` (judged frames only)."""

    start: int
    stop: int
    information_min: float
    information_median: float
    information_max: float
    degenerate_frames: int | None
    tracking_s_median: float


def range_quality(timings: dict, start: int, stop: int) -> RangeQuality:
    """Summarise frames [start, stop) of a timings.json's per-frame lists; frames the
    tracker did not judge (null information, e.g. the first) are left out."""
    information = [
        value for value in timings["tracking_information"][start:stop] if value is not None
    ]
    if not information:
        raise SystemExit(f"frames {start}-{stop - 1}: no frame with a tracking_information")
    directions = [
        value
        for value in timings["tracking_degenerate_directions"][start:stop]
        if value is not None
    ]
    return RangeQuality(
        start=start,
        stop=stop,
        information_min=min(information),
        information_median=statistics.median(information),
        information_max=max(information),
        degenerate_frames=sum(value > 0 for value in directions) if directions else None,
        tracking_s_median=statistics.median(timings["tracking_s"][start:stop]),
    )


def table(ranges: list[RangeQuality]) -> str:
    """The ranges as a markdown table."""
    lines = [
        "| frames | information min | median | max | degenerate frames "
        "| tracking (s/frame, median) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in ranges:
        degenerate = "-" if r.degenerate_frames is None else str(r.degenerate_frames)
        lines.append(
            f"| {r.start}-{r.stop - 1} | {r.information_min:.3g} | {r.information_median:.3g} "
            f"| {r.information_max:.3g} | {degenerate} | {r.tracking_s_median:.3f} |"
        )
    return "\n".join(lines) + "\n"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", type=Path, help="a run folder (holds timings.json)")
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--bounds", type=int, nargs="+", help="range edges, increasing")
    group.add_argument("--every", type=int, help="frames per range, from frame 0")
    args = parser.parse_args(argv)
    if args.every is not None and args.every < 1:
        parser.error("--every must be >= 1")
    if args.bounds is not None and (
        len(args.bounds) < 2 or args.bounds != sorted(set(args.bounds)) or args.bounds[0] < 0
    ):
        parser.error("--bounds must be at least two increasing frame indices >= 0")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    path = args.run / "timings.json"
    try:
        timings = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise SystemExit(f"{path}: cannot read ({error}); give a finished run folder") from None
    if "tracking_information" not in timings:
        raise SystemExit(f"{path}: no per-frame tracking quality (a tracker that judges itself)")
    frames = len(timings["tracking_s"])
    edges = args.bounds if args.bounds is not None else [*range(0, frames, args.every), frames]
    edges = [min(edge, frames) for edge in edges]
    ranges = [range_quality(timings, a, b) for a, b in itertools.pairwise(edges) if b > a]
    print(f"{args.run}: {frames} frames")
    print(table(ranges), end="")


if __name__ == "__main__":
    main()
