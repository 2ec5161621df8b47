"""Mesh extraction: marching cubes of the learned TSDF, block by block (docs/method.md section 6).

The grid of step ``resolution`` over the field's bound is never held whole. It is cut
into blocks (:mod:`eslam.mesh.grid`); per block:

1. the TSDF is evaluated on a coarse grid (step about T / 2) and only coarse cells
   that may hold the zero level are kept (a sign change, or a corner within twice the
   cell's half-diagonal of the surface);
2. the TSDF is evaluated at the fine points of those cells only;
3. with keyframes given, a fine cell is meshed only when all 8 of its corners are in
   observed space (:mod:`eslam.mesh.observed`), so unobserved space produces no
   phantom surfaces; blocks no keyframe frustum reaches are skipped unevaluated;
4. marching cubes (scikit-image, level 0) runs on the block's meshed cells.

Blocks share their boundary points, and vertices on the same grid edge are welded
(:mod:`eslam.mesh.weld`), so the result is the mesh a single dense marching cubes over
the same cells gives. Memory per block is O(block_cells^3) plus O(chunk) per field
query, whatever the bound. Vertex colours come from the appearance decoder.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch

from eslam.mesh.grid import (
    ExtractionGrid,
    all_corners,
    cell_points,
    crossing_cells,
    make_grid,
    near_surface_threshold,
    refine_cells,
    surface_cells,
)
from eslam.mesh.observed import (
    ObservedViews,
    observed_box,
    observed_mask,
    views_seeing_boxes,
)
from eslam.mesh.weld import weld_vertices
from eslam.types import FieldOutput, TriangleMesh

__all__ = ["ExtractOptions", "ObservedViews", "TSDFField", "extract_mesh", "observed_mask"]

COARSE_STEP_FRACTION = 0.5
"""Default coarse step, in units of the truncation T (rounded to whole fine steps: 3 at
1 cm, 2 at 2 cm for T = 6 cm): the near-surface test (|sdf| * T <= 2 * half-diagonal,
about 0.87 T) then stays inside the truncation band, where the TSDF measures distance."""

DEFAULT_BLOCK_CELLS = 64
"""Fine cells per block side: 65^3 points, ~1.4 MB of float32 TSDF per block."""

DEFAULT_CHUNK = 262144
"""Points per field query (bounds the decoder's activations)."""


class TSDFField(Protocol):
    """What extraction needs of a field (:class:`eslam.field.scene_field.SceneField`).

    Attributes:
        bound: (3, 2) scene box, metres.
        truncation: T, metres; ``query(...).sdf`` is in units of T.
    """

    bound: torch.Tensor
    truncation: float

    def query(self, points: torch.Tensor, with_rgb: bool = True) -> FieldOutput: ...


@dataclass(frozen=True)
class ExtractOptions:
    """How the grid is cut and queried.

    Attributes:
        block_cells: fine cells per block side (rounded to a multiple of the coarse
            factor); a block holding the whole grid gives a dense single-block pass.
        coarse_step: coarse grid step, metres; None = COARSE_STEP_FRACTION * T.
        chunk: points per field query.
    """

    block_cells: int = DEFAULT_BLOCK_CELLS
    coarse_step: float | None = None
    chunk: int = DEFAULT_CHUNK

    def __post_init__(self) -> None:
        if self.block_cells < 1 or self.chunk < 1:
            raise ValueError("block_cells and chunk must be >= 1")
        if self.coarse_step is not None and self.coarse_step <= 0:
            raise ValueError(f"coarse_step must be > 0, got {self.coarse_step}")


@dataclass(frozen=True, eq=False)
class _Piece:
    """One block's marching-cubes output: (V, 3) float64 vertices in global grid steps
    and (F, 3) int64 faces."""

    vertices: np.ndarray
    faces: np.ndarray


def _device(field: TSDFField) -> torch.device:
    return field.bound.device


def _query_sdf(field: TSDFField, points: np.ndarray, chunk: int) -> np.ndarray:
    """(M,) float32 TSDF at (M, 3) float64 points, ``chunk`` points per query."""
    values = np.empty(points.shape[0], dtype=np.float32)
    device = _device(field)
    for start in range(0, points.shape[0], chunk):
        batch = torch.from_numpy(points[start : start + chunk]).to(device, torch.float32)
        values[start : start + chunk] = field.query(batch, with_rgb=False).sdf.float().cpu()
    return values


def _query_rgb(field: TSDFField, points: np.ndarray, chunk: int) -> np.ndarray:
    """(M, 3) uint8 colour at (M, 3) float64 points."""
    colours = np.empty((points.shape[0], 3), dtype=np.uint8)
    device = _device(field)
    for start in range(0, points.shape[0], chunk):
        batch = torch.from_numpy(points[start : start + chunk]).to(device, torch.float32)
        rgb = field.query(batch, with_rgb=True).rgb
        colours[start : start + chunk] = (rgb.clamp(0, 1) * 255).round().byte().cpu().numpy()
    return colours


def _observed(points: np.ndarray, views: ObservedViews, visible: list[int], chunk: int):
    """(M,) bool observed mask of (M, 3) float64 points, ``chunk`` points at a time."""
    seen = np.empty(points.shape[0], dtype=bool)
    for start in range(0, points.shape[0], chunk):
        batch = torch.from_numpy(points[start : start + chunk])
        seen[start : start + chunk] = observed_mask(batch, views, visible).cpu().numpy()
    return seen


def _blocks_to_visit(
    grid: ExtractionGrid, views: ObservedViews | None
) -> list[tuple[tuple[int, int, int], list[int] | None]]:
    """The blocks worth meshing, each with the views that may see it (None: no views)."""
    counts = np.asarray(grid.blocks)
    if views is None:
        blocks = np.indices(counts).reshape(3, -1).T
        return [(tuple(int(i) for i in b), None) for b in blocks]
    if len(views) == 0:
        return []
    low, high = observed_box(views)
    size = grid.block_cells * grid.step
    first = np.clip(np.floor((low - grid.origin) / size).astype(np.int64), 0, counts - 1)
    last = np.clip(np.floor((high - grid.origin) / size).astype(np.int64), 0, counts - 1)
    if np.any(high < grid.origin) or np.any(low > grid.origin + counts * size):
        return []
    blocks = np.indices(last - first + 1).reshape(3, -1).T + first
    lower, upper = grid.block_box(blocks)
    seeing = views_seeing_boxes(lower, upper, views)
    return [
        (tuple(int(i) for i in block), np.flatnonzero(row).tolist())
        for block, row in zip(blocks, seeing, strict=True)
        if row.any()
    ]


def _grid_points(axes: list[np.ndarray]) -> np.ndarray:
    """(X*Y*Z, 3) points of the grid with the given per-axis positions (C order)."""
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _surface_cells_of_block(
    field: TSDFField, grid: ExtractionGrid, start: np.ndarray, near: float, chunk: int
) -> tuple[np.ndarray, np.ndarray]:
    """Coarse pass: the block's coarse TSDF and its coarse cells that may hold surface."""
    per_block = grid.block_cells // grid.factor
    axes = grid.fine_positions(start, per_block + 1, stride=grid.factor)
    sdf = _query_sdf(field, _grid_points(axes), chunk).reshape((per_block + 1,) * 3)
    cells = surface_cells(sdf, near)
    inside = np.asarray(grid.coarse_cells) - start // grid.factor  # cells left in the grid
    cells[inside[0] :] = False
    cells[:, inside[1] :] = False
    cells[:, :, inside[2] :] = False
    return sdf, cells


def _mesh_block(
    field: TSDFField,
    grid: ExtractionGrid,
    block: tuple[int, int, int],
    views: tuple[ObservedViews, list[int]] | None,
    near: float,
    chunk: int,
) -> _Piece | None:
    """Marching cubes over one block's surface cells in observed space (None: nothing)."""
    from skimage.measure import marching_cubes

    start = grid.block_start(block)
    coarse_sdf, coarse_cells = _surface_cells_of_block(field, grid, start, near, chunk)
    if not coarse_cells.any():
        return None
    cells = refine_cells(coarse_cells, grid.factor)
    needed = cell_points(cells)
    index = np.nonzero(needed)
    axes = grid.fine_positions(start, grid.block_cells + 1)
    points = np.stack([axes[a][index[a]] for a in range(3)], axis=1)
    if grid.factor == 1:
        sdf = coarse_sdf
    else:
        sdf = np.ones(needed.shape, dtype=np.float32)
        sdf[index] = _query_sdf(field, points, chunk)
    if views is not None:
        observed = np.zeros(needed.shape, dtype=bool)
        observed[index] = _observed(points, views[0], views[1], chunk)
        cells &= all_corners(observed)
    cells &= crossing_cells(sdf)
    if not cells.any():
        return None
    # scikit-image processes a cell when the mask is set at its upper corner (x+1, y+1, z+1)
    mask = np.zeros(needed.shape, dtype=bool)
    mask[1:, 1:, 1:] = cells
    try:
        vertices, faces, _, _ = marching_cubes(sdf, level=0.0, mask=mask, allow_degenerate=False)
    except RuntimeError:  # "No surface found": every crossing was degenerate
        return None
    return _Piece(vertices=vertices.astype(np.float64) + start, faces=faces.astype(np.int64))


@torch.no_grad()
def extract_mesh(
    field: TSDFField,
    resolution: float,
    views: ObservedViews | None = None,
    options: ExtractOptions = ExtractOptions(),
) -> TriangleMesh:
    """Marching cubes of ``field``'s TSDF at level 0 on a grid of step ``resolution`` metres.

    Args:
        field: the field (any device); its ``bound`` is the box meshed.
        resolution: grid step, metres (docs/method.md section 6: 0.01 Replica/TUM, 0.02 ScanNet).
        views: observed space; None meshes the whole bound (phantom surfaces possible).
        options: block size, coarse step and query chunk.

    Returns:
        The mesh in world coordinates, vertices welded across blocks, with vertex
        colours from the appearance decoder; empty when no surface is found.
    """
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0, got {resolution}")
    bound = field.bound.detach().cpu().double().numpy()
    truncation = float(field.truncation)
    coarse = options.coarse_step or COARSE_STEP_FRACTION * truncation
    grid = make_grid(bound[:, 0], bound[:, 1], resolution, coarse, options.block_cells)
    near = near_surface_threshold(grid.coarse_step, truncation)
    pieces = []
    for block, visible in _blocks_to_visit(grid, views):
        seen = None if views is None else (views, visible)
        piece = _mesh_block(field, grid, block, seen, near, options.chunk)
        if piece is not None:
            pieces.append(piece)
    if not pieces:
        return _empty_mesh()
    offsets = np.cumsum([0] + [len(p.vertices) for p in pieces[:-1]])
    vertices, faces = weld_vertices(
        np.concatenate([p.vertices for p in pieces]),
        np.concatenate([p.faces + o for p, o in zip(pieces, offsets, strict=True)]),
        grid.fine_points,
    )
    vertices = grid.origin + vertices * grid.step
    colours = _query_rgb(field, vertices, options.chunk)
    return TriangleMesh(vertices=vertices, faces=faces, colours=colours)


def _empty_mesh() -> TriangleMesh:
    return TriangleMesh(
        vertices=np.zeros((0, 3)),
        faces=np.zeros((0, 3), dtype=np.int64),
        colours=np.zeros((0, 3), dtype=np.uint8),
    )
