"""Progress of an evaluation: one tqdm bar per stage on stderr.

``eslam eval`` (and the end of ``eslam demo``) culls two meshes over every frame,
measures distances between hundreds of thousands of samples and casts rays for the
depth L1's virtual views: minutes on a CPU. Each stage gets a bar named after it, with
a count where the stage has one (frames, views), so the wait is never silent; a bar is
closed (left on screen, with its time) when its stage ends or fails, so an error is
printed on a line of its own.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from typing import TextIO


def _ignore(done: int) -> None:
    """The ``advance`` of a stage nobody watches."""


class StageProgress:
    """Bars for the stages of an evaluation (nothing when off).

    Args:
        enabled: draw the bars.
        file: where to draw them (default: stderr, looked up per stage).
    """

    def __init__(self, enabled: bool, file: TextIO | None = None) -> None:
        self.enabled = enabled
        self.file = file

    @contextlib.contextmanager
    def stage(
        self, name: str, total: int = 1, unit: str = "step"
    ) -> Iterator[Callable[[int], None]]:
        """A bar named ``name`` over ``total`` items while inside; yields ``advance(done)``
        to report ``done`` items finished so far. A stage without a count (``total`` = 1)
        shows 1/1 with its time when it ends."""
        if not self.enabled:
            yield _ignore
            return
        from tqdm import tqdm

        file = self.file if self.file is not None else sys.stderr
        with tqdm(total=total, desc=name, unit=unit, file=file) as bar:

            def advance(done: int) -> None:
                bar.update(done - bar.n)

            yield advance
            if total == 1 and bar.n == 0:
                bar.update(1)
