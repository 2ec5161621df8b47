"""View filters: pixels a frame is not tracked on, chosen before the tracker runs.

A filter answers which of a frame's pixels to keep, given the frame's
:class:`~eslam.slam.views.View`, the motion model's guess and the run's state; the
tracking front end (:mod:`eslam.slam.tracking.frontend`) applies its filters in order and tracks
on what is left. Filters are built by name from :data:`VIEW_FILTERS` with the run's
:class:`~eslam.slam.context.RunContext`; :func:`configured_filters` lists the names the
config turns on.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import torch

from eslam.config import ESLAMConfig
from eslam.registry import Registry
from eslam.slam.context import RunContext
from eslam.slam.tracking.observed_view import observed_pixels
from eslam.slam.views import View

if TYPE_CHECKING:
    from eslam.slam.state import SLAMState


class ViewFilter(Protocol):
    """Chooses the pixels of a frame to track on."""

    name: str
    """Its name (the one it is registered under)."""

    emptied: str
    """What the log says of a frame it leaves no pixel: why none is left."""

    def keep(self, view: View, guess: torch.Tensor, state: SLAMState) -> torch.Tensor:
        """(P,) bool on the view's device: the pixels of ``view`` to keep, with the
        frame's camera-to-world pose guessed as ``guess`` (4, 4)."""
        ...


class ObservedSpace:
    """Keeps the pixels in space a keyframe observed (``tracking.observed_only``;
    :mod:`eslam.slam.tracking.observed_view`)."""

    name = "observed"
    emptied = "none of its pixels lies in space a keyframe observed (tracking.observed_only)"

    def keep(self, view: View, guess: torch.Tensor, state: SLAMState) -> torch.Tensor:
        return observed_pixels(view, guess, state.observed_views())


VIEW_FILTERS: Registry[ViewFilter] = Registry("view filter", "view filter")
"""View filters by name; a factory takes the run's :class:`RunContext`."""
VIEW_FILTERS.register("observed", lambda context: ObservedSpace())


def configured_filters(config: ESLAMConfig) -> tuple[str, ...]:
    """The names of the view filters ``config`` turns on, in the order they apply."""
    return ("observed",) if config.tracking.observed_only else ()


def make_filters(context: RunContext) -> list[ViewFilter]:
    """The view filters the run's config turns on, built for ``context``."""
    return [VIEW_FILTERS.make(name, context) for name in configured_filters(context.config)]
