"""Count the optimiser steps of a call that takes no callback (the mapping call).

:func:`eslam.slam.mapping.map_window` runs its iterations without reporting them; the
run loop still tells its observers about each one
(:class:`~eslam.slam.observers.MappingStep` events: the progress of the first frame's
long mapping call) by listening to optimiser steps while the call runs. Only the steps
of optimisers that hold the given parameter are counted (not another run's in another
thread), the hook is removed when the call ends, and nothing is read from the device:
a count, never a loss, so no host sync is added."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

import torch
from torch.optim.optimizer import register_optimizer_step_post_hook


@contextlib.contextmanager
def counting_steps(parameter: torch.Tensor, on_step: Callable[[int], None]) -> Iterator[None]:
    """While inside, call ``on_step(k)`` after the k-th step (1, 2, ...) of any optimiser
    that optimises ``parameter`` (identity, not equality). The call runs on the thread
    that steps the optimiser (the run's own)."""
    count = 0

    def after_step(optimiser: torch.optim.Optimizer, args: object, kwargs: object) -> None:
        nonlocal count
        if any(p is parameter for group in optimiser.param_groups for p in group["params"]):
            count += 1
            on_step(count)

    handle = register_optimizer_step_post_hook(after_step)
    try:
        yield
    finally:
        handle.remove()
