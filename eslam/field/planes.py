"""Multi-scale axis-aligned feature planes (docs/method.md section 1).

Coordinates: a world point p (metres) inside the scene bound [b_min, b_max] maps to
p_n = 2 (p - b_min) / (b_max - b_min) - 1 in [-1, 1]^3. Each level of a plane set holds
three planes, laid out as in the release:

    xy: (C, ny, nx) sampled at (x, y)
    xz: (C, nz, nx) sampled at (x, z)
    yz: (C, nz, ny) sampled at (y, z)

A level's three planes live in ONE parameter tensor of shape (3, C, Hmax, Wmax), each
plane in the top-left corner ``[i, :, :h_i, :w_i]`` and zeros beyond (the padding gets
no gradient). Four samplings read the same parameters (``FieldConfig.plane_sampling``):

* reference: each plane sliced out and sampled alone by ``grid_sample`` (readable);
* fast: a level's three planes in one batched ``grid_sample`` call;
* fused: every level of the field (geometry and appearance, coarse and fine) in one op
  of row gathers from channels-last planes with a hand-written backward
  (:mod:`eslam.field.fused_sampling`); the planes are then stored channels-last;
* triton: the fused sampling's maths in Triton kernels, one launch per level, for CUDA
  (:mod:`eslam.field.triton_sampling`; channels-last planes too).

Each is a sampler in :data:`eslam.field.plane_sampling.PLANE_SAMPLINGS` (with the
per-level functions ``sample_planes_reference`` and ``sample_planes_fast``).

tests/field/test_planes.py, test_fused_sampling.py and test_triton_sampling.py hold them
equal.

Over 400 lines on purpose: a level's planes, their growth with the scene bound
(windows, re-gridding) and the plane set combining the levels are one structure; the
sampling maths live in :mod:`eslam.field.plane_sampling`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from torch import nn

from eslam.field.plane_sampling import (
    PLANE_AXES,
    PLANE_SAMPLINGS,
    PlaneSampler,
    PlaneShapes,
    grid_scale,
    padding_mask,
)

ROUNDING_TOLERANCE = 1e-4
"""Slack (in cells) when dividing an extent by a cell size, so that 4.8 / 0.24 is 20
cells and not 19 or 21 after float rounding; also makes :func:`fit_bound` idempotent."""


def fit_bound(bound: torch.Tensor, multiple: float) -> torch.Tensor:
    """Grow the bound's upper corner so each side is a multiple of ``multiple`` (release).

    b_max' = b_min + ceil((b_max - b_min) / multiple) * multiple; a side that already is
    a multiple (up to :data:`ROUNDING_TOLERANCE` cells) keeps its length.

    Args:
        bound: (3, 2) [[xmin, xmax], [ymin, ymax], [zmin, zmax]], metres, min < max.
        multiple: side length quantum, metres (release: 0.24).

    Returns:
        (3, 2) the fitted bound, same dtype and device as ``bound``.

    Example:
        [[0, 1], [0, 0.5], [-1, 1]] with 0.24 -> [[0, 1.2], [0, 0.72], [-1, 1.16]].
    """
    _check_bound(bound)
    if multiple <= 0:
        raise ValueError(f"multiple must be positive, got {multiple}")
    low = bound[:, 0].double()
    cells = torch.ceil((bound[:, 1].double() - low) / multiple - ROUNDING_TOLERANCE)
    high = low + cells.clamp(min=1) * multiple
    return torch.stack((low, high), dim=1).to(bound)


def enclosing_bound(bound: torch.Tensor, required: torch.Tensor, multiple: float) -> torch.Tensor:
    """The fitted bound grown by whole ``multiple`` steps on each side to hold ``required``.

    Lower corners move down by whole multiples, upper corners follow :func:`fit_bound`,
    so a side of the result is still a multiple of ``multiple`` and the result holds
    ``bound`` exactly; sides ``required`` does not cross are unchanged.

    Args:
        bound: (3, 2) a fitted scene box, metres.
        required: (3, 2) the box to hold, metres.
        multiple: side length quantum, metres (``FieldConfig.bound_multiple``).

    Returns:
        (3, 2) float64 on the CPU.
    """
    _check_bound(bound)
    old = bound.detach().cpu().double()
    need = required.detach().cpu().double()
    steps = torch.ceil((old[:, 0] - need[:, 0]) / multiple - ROUNDING_TOLERANCE).clamp(min=0)
    low = old[:, 0] - steps * multiple
    high = fit_bound(torch.stack((low, torch.maximum(old[:, 1], need[:, 1])), dim=1), multiple)[
        :, 1
    ]
    # sides that need not grow keep their exact value (no rounding drift)
    high = torch.where(need[:, 1] > old[:, 1], high, old[:, 1])
    return torch.stack((low, high), dim=1)


def normalize_points(points: torch.Tensor, bound: torch.Tensor) -> torch.Tensor:
    """Map world points into the bound's normalised cube (docs/method.md section 1, release).

    p_n = 2 (p - b_min) / (b_max - b_min) - 1; inside the bound p_n is in [-1, 1].

    Args:
        points: (N, 3) world coordinates, metres.
        bound: (3, 2) scene box, metres.

    Returns:
        (N, 3) normalised coordinates, dtype of ``points``.
    """
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {tuple(points.shape)}")
    bound = bound.to(points)
    return 2.0 * (points - bound[:, 0]) / (bound[:, 1] - bound[:, 0]) - 1.0


def grid_size(bound: torch.Tensor, resolution: float) -> tuple[int, int, int]:
    """Vertices per axis (nx, ny, nz) = int(extent / resolution) (docs/method.md section 1).

    At least 2 per axis, so that every axis is resolved even by a cell size larger than
    the bound (a case the release does not guard).

    Args:
        bound: (3, 2) fitted scene box, metres.
        resolution: cell size, metres.

    Example:
        extents 4.8 x 2.4 x 2.4 m at 0.24 m -> (20, 10, 10).
    """
    _check_bound(bound)
    extent = (bound[:, 1].double() - bound[:, 0].double()).tolist()
    nx, ny, nz = (max(2, math.floor(e / resolution + ROUNDING_TOLERANCE)) for e in extent)
    return nx, ny, nz


def plane_shapes(grid: Sequence[int]) -> PlaneShapes:
    """The (height, width) of the xy, xz, yz planes for a grid of (nx, ny, nz) vertices."""
    nx, ny, nz = grid
    return (ny, nx), (nz, nx), (nz, ny)


IDENTITY_WINDOW = ((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))
"""A level's window when its vertices span exactly the scene bound (every fresh level)."""


def to_window(points_n: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
    """Normalised scene coordinates -> a level's own [-1, 1] coordinates.

    q = 2 (p_n - w_min) / (w_max - w_min) - 1, with ``window`` (3, 2) the box the level's
    first and last vertices span, in the scene's normalised coordinates.
    """
    window = window.to(points_n)
    return 2.0 * (points_n - window[:, 0]) / (window[:, 1] - window[:, 0]) - 1.0


@dataclass(frozen=True)
class LevelGrowth:
    """How a level's vertex grid grows to cover a larger scene bound.

    Attributes:
        low: vertices added before the first one, per axis (x, y, z).
        grid: the new vertex counts (nx, ny, nz) = old + low + added after the last.
        window: (3, 2) float64 the new grid's box in the NEW bound's normalised coordinates.
    """

    low: tuple[int, int, int]
    grid: tuple[int, int, int]
    window: torch.Tensor


def level_growth(
    grid: Sequence[int], window: torch.Tensor, old_bound: torch.Tensor, new_bound: torch.Tensor
) -> LevelGrowth:
    """The whole vertices to add on each side so a level's grid covers ``new_bound``.

    The vertex spacing s = (box side) / (n - 1) stays: old vertices keep their world
    positions exactly, shifted by an integer index ``low`` in the grown grid.

    Args:
        grid: current vertex counts (nx, ny, nz).
        window: (3, 2) the level's box in ``old_bound``'s normalised coordinates.
        old_bound: (3, 2) the scene bound ``window`` refers to, metres.
        new_bound: (3, 2) the larger scene bound to cover, metres.
    """
    old = old_bound.detach().cpu().double()
    new = new_bound.detach().cpu().double()
    counts = torch.tensor([int(n) for n in grid], dtype=torch.float64)
    box = old[:, :1] + (window.detach().cpu().double() + 1.0) / 2.0 * (old[:, 1:] - old[:, :1])
    spacing = (box[:, 1] - box[:, 0]) / (counts - 1)
    low = torch.ceil((box[:, 0] - new[:, 0]) / spacing - ROUNDING_TOLERANCE).clamp(min=0)
    high = torch.ceil((new[:, 1] - box[:, 1]) / spacing - ROUNDING_TOLERANCE).clamp(min=0)
    grown = torch.stack((box[:, 0] - low * spacing, box[:, 1] + high * spacing), dim=1)
    window_new = 2.0 * (grown - new[:, :1]) / (new[:, 1:] - new[:, :1]) - 1.0
    low_cells = tuple(int(v) for v in low.tolist())
    new_grid = tuple(int(n + a + b) for n, a, b in zip(grid, low_cells, high.tolist(), strict=True))
    return LevelGrowth(low=low_cells, grid=new_grid, window=window_new)  # type: ignore[arg-type]


def grow_planes(
    planes: torch.Tensor,
    shapes: PlaneShapes,
    growth: LevelGrowth,
    init_std: float,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """A level's padded planes on its grown grid: old features copied, new ones drawn.

    Plane i (axes (a, b) of :data:`PLANE_AXES`) moves to rows ``low[b]:`` and columns
    ``low[a]:`` of the new plane; the rest of the new plane is normal(0, init_std)
    from ``generator`` (as fresh planes are), the padding zero.

    Args:
        planes: (3, C, Hmax, Wmax) the level's current padded planes.
        shapes: their true (h, w).
        growth: from :func:`level_growth`.
        init_std: standard deviation of the new features.
        generator: random source (on the planes' device); None = torch's global one.

    Returns:
        (3, C, Hmax', Wmax') detached tensor on the planes' device and dtype.
    """
    new_shapes = plane_shapes(growth.grid)
    height = max(h for h, _ in new_shapes)
    width = max(w for _, w in new_shapes)
    old = planes.detach()
    grown = torch.zeros(3, old.shape[1], height, width, dtype=old.dtype, device=old.device)
    for i, ((h, w), (nh, nw), (a, b)) in enumerate(
        zip(shapes, new_shapes, PLANE_AXES, strict=True)
    ):
        fresh = torch.empty(old.shape[1], nh, nw, dtype=old.dtype, device=old.device)
        grown[i, :, :nh, :nw] = fresh.normal_(0.0, init_std, generator=generator)
        row, col = growth.low[b], growth.low[a]
        grown[i, :, row : row + h, col : col + w] = old[i, :, :h, :w]
    return grown


class PlaneLevel(nn.Module):
    """One level of a plane set: the xy, xz and yz planes of one resolution.

    Attributes:
        planes: (3, C, Hmax, Wmax) parameter; plane i is ``planes[i, :, :h_i, :w_i]``,
            initialised normal(0, init_std) (release), zero padding beyond.
        shapes: the true (h, w) of the xy, xz, yz planes.
        sampling: "reference", "fast", "fused" or "triton" (module doc); "fused" and
            "triton" store the planes channels-last (same shape and values, other strides).
        window: (3, 2) buffer (in the state_dict): the box the first and last vertices
            span, in the scene's normalised coordinates; [-1, 1] on every axis until the
            scene bound grows (:meth:`grow`), then wider, so old vertices stay in place.
        vertices: (3,) int64 buffer (in the state_dict): the grid (nx, ny, nz).
    """

    def __init__(
        self,
        grid: Sequence[int],
        channels: int,
        init_std: float,
        sampling: str = "fast",
        generator: torch.Generator | None = None,
    ):
        """Planes for a grid of (nx, ny, nz) vertices with ``channels`` features each.

        Features start as N(0, init_std^2) draws from ``generator`` (a CPU generator;
        None: torch's global one).
        """
        super().__init__()
        self.sampler: PlaneSampler = PLANE_SAMPLINGS.make(sampling)
        self.sampling = sampling
        self.init_std = float(init_std)
        grid = tuple(int(n) for n in grid)
        shapes = plane_shapes(grid)
        planes = torch.zeros(3, channels, max(h for h, _ in shapes), max(w for _, w in shapes))
        for i, (h, w) in enumerate(shapes):
            planes[i, :, :h, :w].normal_(0.0, init_std, generator=generator)
        self.register_buffer("window", torch.tensor(IDENTITY_WINDOW))
        self.register_buffer("vertices", torch.tensor(grid, dtype=torch.int64))
        self._set_grid(grid, planes)

    def _set_grid(self, grid: tuple[int, int, int], planes: torch.Tensor) -> None:
        """Install ``planes`` (3, C, Hmax, Wmax) for a grid of (nx, ny, nz) vertices."""
        self.grid = grid
        self.shapes = plane_shapes(grid)
        height, width = planes.shape[2], planes.shape[3]
        device = planes.device
        if self.sampler.rows:  # rows of C features contiguous: read them whole
            planes = planes.contiguous(memory_format=torch.channels_last)
        self.planes = nn.Parameter(planes)
        self.vertices = torch.tensor(grid, dtype=torch.int64, device=self.vertices.device)
        self.register_buffer(
            "padding", padding_mask(self.shapes, height, width, device), persistent=False
        )
        self.register_buffer(
            "scale", grid_scale(self.shapes, height, width, device), persistent=False
        )
        self._refresh_window()

    def _refresh_window(self) -> None:
        window = self.window.detach().cpu()
        self._identity = bool(torch.equal(window, torch.tensor(IDENTITY_WINDOW).to(window)))
        # the window as Python numbers for the fused op (read once here, not per query)
        self._window_bounds = None if self._identity else tuple(map(tuple, window.tolist()))

    def grow(self, growth: LevelGrowth, generator: torch.Generator | None = None) -> None:
        """Enlarge the grid as ``growth`` says, keeping every old feature at its vertex.

        Replaces the ``planes`` parameter: optimisers holding the old one must be rebuilt.
        """
        planes = grow_planes(self.planes, self.shapes, growth, self.init_std, generator)
        self.window = growth.window.to(self.window)
        self._set_grid(growth.grid, planes)

    def reshape_like(self, vertices: torch.Tensor, window: torch.Tensor) -> None:
        """Re-allocate (zero) planes for a saved grid, so a grown level's state can load."""
        grid = tuple(int(n) for n in vertices.tolist())
        shapes = plane_shapes(grid)
        planes = torch.zeros(
            3,
            self.channels,
            max(h for h, _ in shapes),
            max(w for _, w in shapes),
            dtype=self.planes.dtype,
            device=self.planes.device,
        )
        self.window = window.detach().to(self.window)
        self._set_grid(grid, planes)  # type: ignore[arg-type]

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs) -> None:
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)
        self._refresh_window()

    @property
    def channels(self) -> int:
        """Features per plane, C."""
        return self.planes.shape[1]

    def numel_used(self) -> int:
        """Learnable plane entries, padding excluded: C (nx ny + nx nz + ny nz)."""
        return self.channels * sum(h * w for h, w in self.shapes)

    def coordinates(self, points_n: torch.Tensor) -> torch.Tensor:
        """(N, 3) scene-normalised points in this level's own [-1, 1] (its window)."""
        return points_n if self._identity else to_window(points_n, self.window)

    def sample(self, points_n: torch.Tensor) -> torch.Tensor:
        """(N, 3) normalised points -> (N, C) sum of the three planes' bilinear features."""
        return self.sampler.level(self, points_n)

    def extra_repr(self) -> str:
        return f"grid={self.grid}, channels={self.channels}, sampling={self.sampling}"


LEVEL_NAMES = ("coarse", "fine")


class PlaneSet(nn.Module):
    """Geometry or appearance planes: coarse and/or fine level (docs/method.md section 1).

    levels "both" with fusion "concat" (paper): [coarse sum, fine sum] -> 2C features;
    fusion "sum" (ablation d): coarse sum + fine sum -> C; levels "coarse" or "fine"
    (ablations b, c): that level alone -> C.
    """

    def __init__(
        self,
        bound: torch.Tensor,
        resolution: Sequence[float],
        channels: int,
        init_std: float,
        levels: Literal["both", "coarse", "fine"] = "both",
        fusion: Literal["concat", "sum"] = "concat",
        sampling: str = "fast",
        generator: torch.Generator | None = None,
    ):
        """Planes over the fitted (3, 2) ``bound`` with (coarse, fine) cell sizes in metres.

        Initial features are drawn from ``generator`` (CPU; None: torch's global one).
        """
        super().__init__()
        if levels not in ("both", *LEVEL_NAMES):
            raise ValueError(f"levels must be both, coarse or fine, got {levels!r}")
        if fusion not in ("concat", "sum"):
            raise ValueError(f"level_fusion must be concat or sum, got {fusion!r}")
        self.fusion = fusion
        names = LEVEL_NAMES if levels == "both" else (levels,)
        self.levels = nn.ModuleDict(
            {
                name: PlaneLevel(grid_size(bound, res), channels, init_std, sampling, generator)
                for name, res in zip(LEVEL_NAMES, resolution, strict=True)
                if name in names
            }
        )
        concat = fusion == "concat" and len(self.levels) > 1
        self.out_dim = channels * (len(self.levels) if concat else 1)

    def features(self, points_n: torch.Tensor) -> torch.Tensor:
        """(N, 3) normalised points -> (N, out_dim) features, levels coarse then fine."""
        return self.combine([level.sample(points_n) for level in self.levels.values()])

    def combine(self, per_level: Sequence[torch.Tensor]) -> torch.Tensor:
        """The (N, out_dim) features from each level's (N, C) ones (coarse then fine)."""
        if self.fusion == "sum":
            return sum(per_level[1:], per_level[0])
        return torch.cat(per_level, dim=-1)

    def numel_used(self) -> int:
        """Learnable plane entries of all levels, padding excluded."""
        return sum(level.numel_used() for level in self.levels.values())

    def grow(
        self,
        old_bound: torch.Tensor,
        new_bound: torch.Tensor,
        generator: torch.Generator | None = None,
    ) -> None:
        """Grow every level's grid from ``old_bound`` to cover ``new_bound`` (see
        :func:`level_growth`); features inside the old grids keep their world positions."""
        for level in self.levels.values():
            level.grow(level_growth(level.grid, level.window, old_bound, new_bound), generator)


def sample_levels_at_once(
    levels: Sequence[PlaneLevel], points_n: torch.Tensor
) -> tuple[torch.Tensor, ...]:
    """Each level's (N, C) features from ONE op over all of them, by the levels' sampler
    (a row sampler's: ``fused`` or ``triton``; one sampling per field)."""
    return levels[0].sampler.levels(levels, points_n)


def fused_features(sets: Sequence[PlaneSet], points_n: torch.Tensor) -> list[torch.Tensor]:
    """Each plane set's (N, out_dim) features, every level of every set sampled in ONE
    op (:func:`sample_levels_at_once`: a row sampler, ``fused`` or ``triton``).

    Equal to ``[s.features(points_n) for s in sets]``.
    """
    levels = [level for planes in sets for level in planes.levels.values()]
    per_level = sample_levels_at_once(levels, points_n)
    features, start = [], 0
    for planes in sets:
        count = len(planes.levels)
        features.append(planes.combine(per_level[start : start + count]))
        start += count
    return features


def _check_bound(bound: torch.Tensor) -> None:
    if bound.shape != (3, 2):
        raise ValueError(f"bound must be (3, 2) [[xmin, xmax], ...], got {tuple(bound.shape)}")
    if not bool((bound[:, 1] > bound[:, 0]).all()):
        raise ValueError(f"bound must have min < max on every axis, got {bound.tolist()}")
