"""Keyframe windows: which keyframes a mapping call optimises together.

Every strategy keeps the current keyframe and the two latest others (the paper's
required rows) and fills the window up to ``mapping.window`` keyframes: ``random``
draws the rest from all keyframes (the paper), ``overlap`` from those that see the
current keyframe's points (the release), ``recent`` takes the latest (a sliding
window). Strategies are chosen by ``mapping.selection`` from :data:`WINDOWS`.

The policies are small frozen dataclasses whose only state is their settings; their
randomness comes from the ``torch.Generator`` passed to ``select``, so a seeded run
draws the same windows every time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch

from eslam.config import MappingConfig
from eslam.geometry.camera import pixels_to_camera_directions
from eslam.registry import Registry
from eslam.slam.mapping.keyframes import KeyframeStore

MIN_VISIBLE_DEPTH = 1e-6
"""Metres: points closer to a camera (or behind it) are not in its view."""


class WindowStrategy(Protocol):
    """Chooses the keyframes optimised together when a frame is mapped."""

    size: int

    def select(
        self, store: KeyframeStore, current: int, generator: torch.Generator | None = None
    ) -> list[int]:
        """Sorted keyframe ids of the window; always holds ``current`` and the two latest."""
        ...


def _required(count: int, current: int) -> list[int]:
    """``current`` and the two latest other keyframes (fewer when there are fewer)."""
    if not 0 <= current < count:
        raise IndexError(f"keyframe {current} out of range (the store holds {count})")
    latest = [k for k in range(count - 1, -1, -1) if k != current][:2]
    return [current, *latest]


def check_window_size(size: int) -> None:
    """Raise unless a window of ``size`` keyframes can hold the current and two latest."""
    if size < 3:
        raise ValueError(f"window size must be >= 3 (current and two latest), got {size}")


def _draw(pool: list[int], count: int, generator: torch.Generator | None) -> list[int]:
    """``count`` items of ``pool`` drawn at random without replacement (all if fewer)."""
    if count <= 0:
        return []
    if count >= len(pool):
        return list(pool)
    device = generator.device if generator is not None else "cpu"
    order = torch.randperm(len(pool), generator=generator, device=device)[:count]
    return [pool[i] for i in order.tolist()]


@dataclass(frozen=True)
class RandomWindow:
    """The paper's window: the current keyframe, the two latest keyframes, and the rest
    (up to ``size`` in all) drawn uniformly without replacement from all other keyframes.

    Attributes:
        size: keyframes in the window, >= 3 (paper: 20).
    """

    size: int = 20

    def __post_init__(self) -> None:
        check_window_size(self.size)

    def select(
        self, store: KeyframeStore, current: int, generator: torch.Generator | None = None
    ) -> list[int]:
        """Sorted keyframe ids of the window (all keyframes when there are at most ``size``)."""
        required = _required(len(store), current)
        pool = [k for k in range(len(store)) if k not in required]
        return sorted(required + _draw(pool, self.size - len(required), generator))


@dataclass(frozen=True)
class OverlapWindow:
    """The release's window: like :class:`RandomWindow`, but the random part is drawn
    only among keyframes that see part of what the current keyframe sees.

    Overlap test: ``samples`` pixels with valid depth are drawn from the current
    keyframe, back-projected with its pose, and projected into every other keyframe;
    a keyframe overlaps when more than ``min_overlap`` of the points land inside its
    image in front of its camera (occlusion is ignored). The default 0 keeps any
    overlap at all, as the NICE-SLAM / ESLAM releases do. When the current keyframe
    has no valid depth, every keyframe counts as overlapping.

    Attributes:
        size: keyframes in the window, >= 3.
        samples: pixels of the current keyframe projected into the others.
        min_overlap: fraction of those points a keyframe must see, in [0, 1).
    """

    size: int = 20
    samples: int = 256
    min_overlap: float = 0.0

    def __post_init__(self) -> None:
        check_window_size(self.size)
        if self.samples < 1 or not 0.0 <= self.min_overlap < 1.0:
            raise ValueError("samples must be >= 1 and min_overlap in [0, 1)")

    def overlap_fractions(
        self,
        store: KeyframeStore,
        current: int,
        keyframes: list[int],
        generator: torch.Generator | None = None,
    ) -> torch.Tensor | None:
        """Fraction of the sampled points each of ``keyframes`` sees.

        Returns:
            (len(keyframes),) float32 fractions in [0, 1] on the store's device, or None
            when the current keyframe has no valid depth.
        """
        intrinsics = store.intrinsics
        depth = store.depth(current).reshape(-1)
        valid = torch.nonzero(depth > 0).squeeze(1)
        if len(valid) == 0:
            return None
        device = generator.device if generator is not None else "cpu"
        pick = torch.randperm(len(valid), generator=generator, device=device)[: self.samples]
        pixels = valid[pick.to(valid.device)]
        uv = torch.stack((pixels % intrinsics.width, pixels // intrinsics.width), dim=-1)
        directions = pixels_to_camera_directions(uv.to(torch.float32), intrinsics)
        points_cam = directions * depth[pixels].unsqueeze(-1)
        c2w = store.poses[current]
        points = points_cam @ c2w[:3, :3].T + c2w[:3, 3]
        poses = store.poses[keyframes]
        # Row-vector form of R^T (p - t) for every keyframe at once: (K, P, 3).
        local = (points.unsqueeze(0) - poses[:, None, :3, 3]) @ poses[:, :3, :3]
        z = local[..., 2]
        safe_z = torch.where(z > MIN_VISIBLE_DEPTH, z, torch.ones_like(z))
        u = intrinsics.fx * local[..., 0] / safe_z + intrinsics.cx
        v = intrinsics.fy * local[..., 1] / safe_z + intrinsics.cy
        inside = (
            (z > MIN_VISIBLE_DEPTH)
            & (u >= -0.5)
            & (u < intrinsics.width - 0.5)
            & (v >= -0.5)
            & (v < intrinsics.height - 0.5)
        )
        return inside.to(torch.float32).mean(dim=1)

    def select(
        self, store: KeyframeStore, current: int, generator: torch.Generator | None = None
    ) -> list[int]:
        """Sorted keyframe ids: current, two latest, the rest drawn among overlapping ones."""
        required = _required(len(store), current)
        pool = [k for k in range(len(store)) if k not in required]
        remaining = self.size - len(required)
        if remaining > 0 and pool:
            fractions = self.overlap_fractions(store, current, pool, generator)
            if fractions is not None:
                keep = (fractions > self.min_overlap).tolist()
                pool = [k for k, kept in zip(pool, keep, strict=True) if kept]
        return sorted(required + _draw(pool, remaining, generator))


@dataclass(frozen=True)
class RecentWindow:
    """A sliding window: the current keyframe and the latest others, ``size`` in all,
    no random draw (the local windows of keyframe odometry, e.g. DVO-SLAM's). The map is
    refitted to recent views only (how it compares with the random window on 7-Scenes:
    docs/results.md, "What we tried and ruled out").

    Attributes:
        size: keyframes in the window, >= 3.
    """

    size: int = 20

    def __post_init__(self) -> None:
        check_window_size(self.size)

    def select(
        self, store: KeyframeStore, current: int, generator: torch.Generator | None = None
    ) -> list[int]:
        """Sorted keyframe ids: current and the latest others (``generator`` is unused)."""
        required = _required(len(store), current)
        pool = [k for k in range(len(store) - 1, -1, -1) if k not in required]
        return sorted(required + pool[: self.size - len(required)])  # size >= 3


WINDOWS: Registry[WindowStrategy] = Registry("window strategy", "mapping.selection")
"""Window strategies by ``mapping.selection``; a factory takes the window's size."""
WINDOWS.register("random", RandomWindow)
WINDOWS.register("overlap", OverlapWindow)
WINDOWS.register("recent", RecentWindow)


def make_window_strategy(config: MappingConfig) -> WindowStrategy:
    """The window policy ``config.selection`` names, of ``config.window`` keyframes."""
    return WINDOWS.make(config.selection, config.window)
