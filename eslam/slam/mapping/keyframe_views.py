"""Keyframes' mapping views, built once per keyframe (``mapping.view_cache_mb``).

A mapping call samples rays from its window's keyframes through
:class:`~eslam.slam.views.View` objects (float colour and depth, the sampling table).
Keyframe images never change once stored, so a keyframe's view is the same at every
call: :class:`KeyframeViews` builds it the first time and keeps it while the memory
budget allows, dropping the least recently used first. A view built again is equal to
the one dropped, so the budget changes memory and speed, never results.
"""

from __future__ import annotations

from collections import OrderedDict

import torch

from eslam.slam.mapping.keyframes import KeyframeStore
from eslam.slam.views import View, make_view

BYTES_PER_MB = 1e6


def view_bytes(view: View) -> int:
    """Bytes held by the tensors of ``view`` (the shared ray directions not counted)."""
    tensors = (view.rgb, view.depth, view.cumulative)
    return sum(t.element_size() * t.nelement() for t in tensors)


class KeyframeViews:
    """The views of a store's keyframes on ``device``, cached within ``budget_mb`` (module doc).

    Args:
        store: the keyframe store.
        directions: (H * W, 3) camera ray directions on ``device``.
        device: where views are built.
        budget_mb: memory for kept views; 0 = keep none.
    """

    def __init__(
        self,
        store: KeyframeStore,
        directions: torch.Tensor,
        device: torch.device,
        budget_mb: float,
    ) -> None:
        self.store = store
        self.directions = directions
        self.device = device
        self.budget_bytes = budget_mb * BYTES_PER_MB
        self._views: OrderedDict[tuple[int, int], View] = OrderedDict()
        self._bytes = 0

    def __len__(self) -> int:
        return len(self._views)

    def view(self, k: int) -> View:
        """The view of keyframe ``k``: kept, or built (and kept when it fits)."""
        key = (k, self.store.frame_indices[k])  # a keyframe id reused after a rollback differs
        kept = self._views.get(key)
        if kept is not None:
            self._views.move_to_end(key)
            return kept
        store = self.store
        built = make_view(store.rgb(k, self.device), store.depth(k, self.device), self.directions)
        size = view_bytes(built)
        if size > self.budget_bytes:
            return built
        while self._bytes + size > self.budget_bytes:
            _, oldest = self._views.popitem(last=False)
            self._bytes -= view_bytes(oldest)
        self._views[key] = built
        self._bytes += size
        return built

    def views(self, keyframes: list[int]) -> list[View]:
        """The views of ``keyframes``, in order."""
        return [self.view(k) for k in keyframes]

    def forget_from(self, count: int) -> None:
        """Drop the views of keyframes ``count`` and later (they were rolled back)."""
        for key in [key for key in self._views if key[0] >= count]:
            self._bytes -= view_bytes(self._views.pop(key))
