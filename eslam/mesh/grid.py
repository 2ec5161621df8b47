"""The extraction grid: fine points, coarse cells and blocks (pure index maths).

Fine grid point (i, j, k) sits at ``origin + (i, j, k) * step``. Every ``factor``-th
fine point along each axis is a coarse point, so a coarse cell holds factor^3 fine
cells. Blocks hold ``block_cells`` fine cells per side (a multiple of ``factor``) and
share their boundary points with their neighbours (one-point overlap), so the cells of
the blocks partition the grid and marching cubes output joins at the seams.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

NEAR_SURFACE_FACTOR = 2.0
"""A coarse cell may hold surface when some corner is within this many times the
half-diagonal of the cell of it (|sdf| * T <= 2 * (sqrt(3) / 2) * coarse step); every
point of a cell is within one half-diagonal of its nearest corner, so an exact SDF
needs factor 1; 2 leaves room for a learned field that is not exactly 1-Lipschitz."""

NEAR_SURFACE_CAP = 0.95
"""The near-surface test never accepts |sdf| above this (TSDF units): values near 1 are
saturated (free space or deep inside) and say nothing about distance. Sound for an exact
SDF while the coarse cell's half-diagonal stays below 0.95 T (coarse step < 1.1 T)."""


def near_surface_threshold(coarse_step: float, truncation: float) -> float:
    """|sdf| (units of T) under which a coarse corner counts as near the surface."""
    half_diagonal = math.sqrt(3) / 2 * coarse_step
    return min(NEAR_SURFACE_FACTOR * half_diagonal / truncation, NEAR_SURFACE_CAP)


@dataclass(frozen=True)
class ExtractionGrid:
    """Geometry of the extraction grid.

    Attributes:
        origin: (3,) float64 position of fine point (0, 0, 0), metres.
        step: fine grid step (the mesh resolution), metres.
        factor: fine cells per coarse cell along each axis.
        coarse_cells: (3,) coarse cells along each axis; the grid spans
            coarse_cells * factor * step metres, covering the requested box.
        block_cells: fine cells per block side (a multiple of ``factor``).
    """

    origin: np.ndarray
    step: float
    factor: int
    coarse_cells: tuple[int, int, int]
    block_cells: int

    @property
    def fine_points(self) -> tuple[int, int, int]:
        """Fine grid points along each axis."""
        return tuple(c * self.factor + 1 for c in self.coarse_cells)

    @property
    def blocks(self) -> tuple[int, int, int]:
        """Blocks along each axis."""
        per_block = self.block_cells // self.factor
        return tuple(math.ceil(c / per_block) for c in self.coarse_cells)

    @property
    def coarse_step(self) -> float:
        """Coarse grid step, metres."""
        return self.step * self.factor

    def block_start(self, block: tuple[int, int, int]) -> np.ndarray:
        """(3,) int64 fine index of the block's first point."""
        return np.asarray(block, dtype=np.int64) * self.block_cells

    def block_box(self, blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) lower and upper corners, metres, of the (N, 3) block indices."""
        lower = self.origin + blocks * self.block_cells * self.step
        return lower, lower + self.block_cells * self.step

    def fine_positions(self, start: np.ndarray, count: int, stride: int = 1) -> list[np.ndarray]:
        """Per axis, the positions (metres) of ``count`` points from fine index
        ``start`` every ``stride`` fine steps."""
        return [
            self.origin[a] + (start[a] + stride * np.arange(count)) * self.step for a in range(3)
        ]


def make_grid(
    lower: np.ndarray, upper: np.ndarray, step: float, coarse_step: float, block_cells: int
) -> ExtractionGrid:
    """The grid of step ``step`` covering the box [lower, upper].

    Args:
        lower, upper: (3,) box corners, metres.
        step: fine step (mesh resolution), metres.
        coarse_step: wanted coarse step, metres; rounded to the nearest whole number
            (at least 1) of fine steps.
        block_cells: wanted fine cells per block side; rounded to a multiple of the
            coarse factor (at least one coarse cell, at most the whole grid).
    """
    factor = max(1, round(coarse_step / step))
    coarse = step * factor
    extent = np.asarray(upper, dtype=np.float64) - np.asarray(lower, dtype=np.float64)
    cells = tuple(max(1, math.ceil(e / coarse - 1e-9)) for e in extent)
    per_block = min(max(1, round(block_cells / factor)), max(cells))
    return ExtractionGrid(
        origin=np.asarray(lower, dtype=np.float64),
        step=float(step),
        factor=factor,
        coarse_cells=cells,
        block_cells=per_block * factor,
    )


def cell_corners(values: np.ndarray) -> list[np.ndarray]:
    """The 8 corner values of every cell of a (X, Y, Z) point array, each (X-1, Y-1, Z-1)."""
    return [
        values[
            i : values.shape[0] - 1 + i, j : values.shape[1] - 1 + j, k : values.shape[2] - 1 + k
        ]
        for i in (0, 1)
        for j in (0, 1)
        for k in (0, 1)
    ]


def surface_cells(sdf: np.ndarray, near: float) -> np.ndarray:
    """(X-1, Y-1, Z-1) bool: cells of the (X, Y, Z) TSDF that may hold the zero level.

    A cell qualifies when its corners change sign or one of them has |sdf| <= ``near``
    (in the TSDF's units).
    """
    low, high, closest = _corner_extremes(sdf)
    return ((low < 0) & (high > 0)) | (closest <= near)


def crossing_cells(sdf: np.ndarray) -> np.ndarray:
    """(X-1, Y-1, Z-1) bool: cells whose corners change sign (or touch 0)."""
    low, high, _ = _corner_extremes(sdf)
    return (low <= 0) & (high >= 0) & (low < high)


def _corner_extremes(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per cell: min, max and min absolute value of its 8 corners (no 8x temporary)."""
    corners = cell_corners(values)
    low, high, closest = corners[0].copy(), corners[0].copy(), np.abs(corners[0])
    for corner in corners[1:]:
        np.minimum(low, corner, out=low)
        np.maximum(high, corner, out=high)
        np.minimum(closest, np.abs(corner), out=closest)
    return low, high, closest


def refine_cells(coarse: np.ndarray, factor: int) -> np.ndarray:
    """Fine-cell mask of a coarse-cell mask: each coarse cell becomes factor^3 cells."""
    fine = coarse
    for axis in range(3):
        fine = np.repeat(fine, factor, axis=axis)
    return fine


def cell_points(cells: np.ndarray) -> np.ndarray:
    """(X+1, Y+1, Z+1) bool: the corner points of the cells set in the (X, Y, Z) mask."""
    points = np.zeros(tuple(n + 1 for n in cells.shape), dtype=bool)
    for i in (0, 1):
        for j in (0, 1):
            for k in (0, 1):
                points[i : i + cells.shape[0], j : j + cells.shape[1], k : k + cells.shape[2]] |= (
                    cells
                )
    return points


def all_corners(points: np.ndarray) -> np.ndarray:
    """(X-1, Y-1, Z-1) bool: cells of the (X, Y, Z) point mask whose 8 corners are all set."""
    result = np.ones(tuple(n - 1 for n in points.shape), dtype=bool)
    for corner in cell_corners(points):
        result &= corner
    return result
