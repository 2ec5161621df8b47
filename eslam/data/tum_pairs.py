"""Colour-depth pairs as TUM RGB-D's own ``associate.py`` makes them
(``data.pairing: associate``; the TUM benchmark's tools, Sturm et al., IROS 2012).

``associate.py`` takes every pair of a colour and a depth time stamp closer than
``max_difference`` (0.02 s by default, its offset 0) as a candidate, sorts the candidates
by time difference (then by colour stamp, then depth stamp: Python's tuple order) and
takes them in that order, each stamp at most once; the pairs come out in time order. No
frame is dropped for being close to the previous one, unlike the ESLAM release's rule
(:func:`eslam.data.tum.associate`), which keeps 759 of fr1/xyz's 798 colour images
where ``associate.py`` pairs 792.
"""

from __future__ import annotations

import numpy as np

ASSOCIATE_MAX_DIFFERENCE = 0.02
"""associate.py's default ``--max_difference``, seconds."""


def unique_pairs(
    colour_times: np.ndarray, depth_times: np.ndarray, max_dt: float = ASSOCIATE_MAX_DIFFERENCE
) -> tuple[np.ndarray, np.ndarray]:
    """(colour rows, depth rows), int64, in colour order: the pairs of the module doc.

    Args:
        colour_times: (N,) seconds, in rgb.txt order.
        depth_times: (M,) seconds, in depth.txt order.
        max_dt: largest time difference, seconds (strictly less, as associate.py).
    """
    order = np.argsort(depth_times, kind="stable")
    ordered = depth_times[order]
    low = np.searchsorted(ordered, colour_times - max_dt, side="left")
    high = np.searchsorted(ordered, colour_times + max_dt, side="right")
    candidates = sorted(
        (abs(float(colour_times[c]) - float(ordered[j])), float(colour_times[c]),
         float(ordered[j]), c, int(order[j]))
        for c in range(len(colour_times))
        for j in range(int(low[c]), int(high[c]))
        if abs(float(colour_times[c]) - float(ordered[j])) < max_dt
    )  # fmt: skip
    used_colour: set[int] = set()
    used_depth: set[int] = set()
    pairs: list[tuple[int, int]] = []
    for *_, c, d in candidates:
        if c not in used_colour and d not in used_depth:
            used_colour.add(c)
            used_depth.add(d)
            pairs.append((c, d))
    rows = np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)
    return rows[:, 0], rows[:, 1]
