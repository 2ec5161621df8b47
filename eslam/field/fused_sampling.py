"""Every plane level of a field sampled in ONE autograd op (``plane_sampling: fused``).

The same bilinear interpolation as the reference
(:func:`eslam.field.plane_sampling.sample_planes_reference`: ``grid_sample`` with
align_corners=True and border padding), computed as weighted sums
of channel rows gathered from channels-last planes. For a plane of true size (h, w) and
a point's plane coordinates (u, v) in a level's [-1, 1] (grid_sample's unnormalisation
and border clip):

    x = clamp((u + 1) / 2 (w - 1), 0, w - 1),    y = clamp((v + 1) / 2 (h - 1), 0, h - 1)
    x0 = min(floor(x), w - 2),  fx = x - x0      (y0, fy alike)
    f = (1-fx)(1-fy) P[y0, x0] + fx (1-fy) P[y0, x0+1] + (1-fx) fy P[y0+1, x0] + fx fy P[y0+1, x0+1]

A level's feature is the sum over its xy, xz and yz planes, so each point reads 12
rows (3 planes x 4 corners) of the level's (3 H W, C) row table: one
``F.embedding_bag`` (mode sum, the bilinear weights as per-sample weights) per level,
without materialising the (N, 12, C) gathered rows. Levels of one grid and window (a
field's coarse geometry and appearance planes, both 0.24 m by default) read the same
rows with the same weights, so they are sampled together: one look-up over their row
tables side by side, split by channel, and one backward over their channels together.

Backward (hand-written, :class:`FusedPlaneSampling`):

* planes: dL/dP[r] = sum over (n, k) with row r of w_nk g_n. On the CPU the 12 N
  look-ups are sorted by row and each row's sum is one bag of a summing
  ``F.embedding_bag`` over the output gradients (:func:`_plane_gradient_sorted`);
  elsewhere ``index_add_`` of the weighted gradients, one look-up k at a time
  (:func:`_plane_gradient_scattered`, the reference the sorted sum is tested against).
  Padding beyond a plane's true size is never read, so it gets exactly zero gradient.
* coordinates: with d_nk = <P[r_nk], g_n> (embedding_bag's per-sample-weight backward),
  df/dfx = (1-fy)(d01 - d00) + fy (d11 - d10), df/dfy = (1-fx)(d10 - d00) + fx (d11 - d01),
  times dx/du = (w - 1) / 2 inside the plane and 0 on or beyond its border (grid_sample's
  border-padding gradient), summed into the point's two coordinates per plane.

The backward is not itself differentiable (double backward raises): the SDF tracker
needs only first derivatives of the TSDF w.r.t. points (``torch.autograd.grad`` without
``create_graph``), and mapping and tracking need first derivatives only.

CUDA: the same op runs on CUDA tensors (embedding_bag and index_add_ have CUDA
kernels; the constants are Python numbers, so the op copies nothing between host and
device and never syncs). The same maths as Triton kernels (one launch per level,
``torch.library`` custom ops) is ``plane_sampling: triton``
(:mod:`eslam.field.triton_sampling`), the explicit CUDA choice: tested against the
reference in Triton's CPU interpreter, not yet run on a GPU; ``fused`` never switches to
it by itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch.autograd.function import once_differentiable

PlaneShapes = tuple[tuple[int, int], ...]

CORNERS = 4
"""Bilinear corners per plane look-up, in the order (y0, x0), (y0, x1), (y1, x0), (y1, x1)."""

LOOKUPS = 3 * CORNERS
"""Rows one point reads from a level: 3 planes x 4 corners."""

EMBEDDING_BAG_SUM = 0
"""The ``mode`` code of a summing embedding_bag in aten's private signatures."""


def row_table(planes: torch.Tensor) -> torch.Tensor:
    """(3 H W, C) rows of a level's (3, C, H, W) planes: row (i H + y) W + x holds the C
    features of plane i at (y, x). A view, no copy, when ``planes`` is channels-last."""
    count, channels, height, width = planes.shape
    return planes.permute(0, 2, 3, 1).reshape(count * height * width, channels)


def level_grid(shapes: PlaneShapes) -> tuple[int, int, int]:
    """The vertex counts (nx, ny, nz) behind a level's plane shapes (ny, nx), (nz, nx),
    (nz, ny) (:func:`eslam.field.planes.plane_shapes`).

    Raises:
        ValueError: the shapes are not those of one grid.
    """
    (ny, nx), (nz, nx2), (nz2, ny2) = shapes
    if (nx, ny, nz) != (nx2, ny2, nz2):
        raise ValueError(f"plane shapes {shapes} are not the xy, xz, yz planes of one grid")
    return nx, ny, nz


def bilinear_corners(
    coords: torch.Tensor, shapes: PlaneShapes, height: int, width: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rows, weights and coordinate derivatives of one level's 12 look-ups per point.

    The planes share their axes (xy and xz read x at the same nx vertices, and so on),
    so the vertex coordinate, cell and fraction are computed once per axis.

    Args:
        coords: (N, 3) the level's own normalised coordinates (NaN reads the lower border,
            as in the reference).
        shapes: the true (h, w) of the xy, xz and yz planes.
        height, width: the padded plane size (H, W) of the row table.

    Returns:
        rows (N, 12) int64 into :func:`row_table`; weights (N, 12) bilinear weights;
        axes (2, N, 3): per axis x, y, z the fraction f and the slope d(vertex)/d(coord)
        (0 where the coordinate is clamped to the border), for the backward.
    """
    grid = level_grid(shapes)
    coords = torch.nan_to_num(coords, nan=-1.0)
    vertex, slope, cell = [], [], []
    for axis, count in enumerate(grid):  # Python constants: no host-to-device copies
        span = count - 1
        position = (coords[:, axis] + 1) / 2 * span
        slope.append(torch.where((position > 0) & (position < span), span / 2, 0.0))
        position = position.clamp(0, span)
        vertex.append(position)
        cell.append(position.floor().clamp(max=max(span - 1, 0)))
    vertex_t, cell_t = torch.stack(vertex, dim=-1), torch.stack(cell, dim=-1)
    fraction = vertex_t - cell_t
    x, y, z = cell_t.to(torch.int64).unbind(-1)
    sx, sy, sz = (int(count > 1) for count in grid)  # 0 along an axis one vertex wide
    plane_size = height * width
    rows = []
    for base, step_u, step_v in (
        (y * width + x, sx, sy * width),
        (plane_size + z * width + x, sx, sz * width),
        (2 * plane_size + z * width + y, sy, sz * width),
    ):
        rows += [base, base + step_u, base + step_v, base + step_v + step_u]
    ends = torch.stack((1 - fraction, fraction), dim=-1)  # (N, 3 axes, 2): cell, next
    ex, ey, ez = ends.unbind(1)
    weights = torch.cat(
        (
            (ey[:, :, None] * ex[:, None, :]).flatten(1),
            (ez[:, :, None] * ex[:, None, :]).flatten(1),
            (ez[:, :, None] * ey[:, None, :]).flatten(1),
        ),
        dim=1,
    )
    return torch.stack(rows, dim=1), weights, torch.stack((fraction, torch.stack(slope, -1)))


def _bag_layout(count: int, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Offsets (N,) and the bag of every look-up (12 N,) of N bags of 12 look-ups each."""
    offsets = torch.arange(0, count * LOOKUPS, LOOKUPS, device=device)
    bag = torch.arange(count, device=device).repeat_interleave(LOOKUPS)
    return offsets, bag


def _plane_gradient(
    grad: torch.Tensor, rows: torch.Tensor, weights: torch.Tensor, layout: tuple[int, int, int]
) -> torch.Tensor:
    """dL/dplanes (3, C, H, W) (channels-last strides): sum_{n,k} w_nk g_n into row r_nk,
    ``layout`` the (3, H, W) of the padded row table, C the gradients' channels.

    The sorted sum on the CPU, the scattered one elsewhere (a GPU adds atomically, and
    the sorted sum's bag offsets would need a host sync there).
    """
    if grad.device.type == "cpu":
        return _plane_gradient_sorted(grad, rows, weights, layout)
    return _plane_gradient_scattered(grad, rows, weights, layout)


def _plane_gradient_scattered(
    grad: torch.Tensor, rows: torch.Tensor, weights: torch.Tensor, layout: tuple[int, int, int]
) -> torch.Tensor:
    """:func:`_plane_gradient` as one ``index_add_`` of (N, C) rows per look-up k."""
    (count_planes, height, width), channels = layout, grad.shape[1]
    table = torch.zeros(
        count_planes * height * width, channels, dtype=grad.dtype, device=grad.device
    )
    for k in range(LOOKUPS):
        table.index_add_(0, rows[:, k], grad * weights[:, k : k + 1])
    return table.view(count_planes, height, width, channels).permute(0, 3, 1, 2)


def _plane_gradient_sorted(
    grad: torch.Tensor, rows: torch.Tensor, weights: torch.Tensor, layout: tuple[int, int, int]
) -> torch.Tensor:
    """:func:`_plane_gradient` as one summing ``F.embedding_bag`` over the gradients.

    The 12 N look-ups, stably sorted by row (int32 keys: an integer radix sort), form
    one bag per table row (offsets from the rows' counts; a row nobody reads is an
    empty bag, zero); bag r sums w_nk g_n over its look-ups, in one fixed order. Faster
    than the 12 scattered adds on the CPU (``benchmarks/plane_gradient.py``;
    docs/benchmarks.md, "Per-iteration timings").
    """
    (count_planes, height, width), channels = layout, grad.shape[1]
    table_rows = count_planes * height * width
    flat = rows.reshape(-1)
    keys = flat.to(torch.int32) if table_rows < 2**31 else flat
    sorted_rows, order = torch.sort(keys, stable=True)
    # the rows' counts by index_add_, not bincount: a size that does not hang on the
    # data (bincount's does, which torch.compile cannot trace without a guard)
    counts = torch.zeros(table_rows, dtype=torch.int64, device=grad.device)
    ones = torch.ones(1, dtype=torch.int64, device=grad.device).expand(flat.numel())
    counts.index_add_(0, sorted_rows, ones)
    offsets = torch.zeros(table_rows, dtype=torch.int64, device=grad.device)
    torch.cumsum(counts[:-1], 0, out=offsets[1:])
    table = F.embedding_bag(
        order // LOOKUPS,
        grad.contiguous(),
        offsets,
        mode="sum",
        per_sample_weights=weights.reshape(-1)[order],
    )
    return table.view(count_planes, height, width, channels).permute(0, 3, 1, 2)


def _coordinate_gradient(
    grad: torch.Tensor,
    rows: torch.Tensor,
    slopes: torch.Tensor,
    table: torch.Tensor,
) -> torch.Tensor:
    """dL/dcoords (N, 3) from the dots d_nk = <P[r_nk], g_n> (module doc), P the (3 H W,
    C) row table (:func:`row_table`; levels of one layout side by side: their dots add).

    The dots come from aten's embedding_bag per-sample-weight backward: faster on the
    tracking workload (2-core CPU, when it was chosen) than one embedding_bag of the
    derivative weights over each axis's 8 corners, and faster still than gathering
    (N, 12, C) rows for a batched matmul. tests/field/test_fused_sampling.py holds it to
    the reference.
    """
    count = grad.shape[0]
    offsets, bag = _bag_layout(count, grad.device)
    dots = torch.ops.aten._embedding_bag_per_sample_weights_backward(
        grad.contiguous(), table, rows.reshape(-1), offsets, bag, EMBEDDING_BAG_SUM
    ).view(count, 3, CORNERS)
    d00, d01, d10, d11 = dots.unbind(-1)
    fraction, slope = slopes
    # planes xy, xz, yz read (u, v) = (x, y), (x, z), (y, z)
    fu, fv = fraction[:, [0, 0, 1]], fraction[:, [1, 2, 2]]
    du = ((1 - fv) * (d01 - d00) + fv * (d11 - d10)) * slope[:, [0, 0, 1]]
    dv = ((1 - fu) * (d10 - d00) + fu * (d11 - d01)) * slope[:, [1, 2, 2]]
    return torch.stack((du[:, 0] + du[:, 1], dv[:, 0] + du[:, 2], dv[:, 1] + dv[:, 2]), dim=1)


Window = tuple[tuple[float, float], ...]
"""A level's box (3 x (low, high)) in the scene's normalised coordinates, or None for
[-1, 1] on every axis (:func:`eslam.field.planes.to_window` as Python numbers)."""


def _to_window(points: torch.Tensor, window: Window | None) -> torch.Tensor:
    """q = 2 (p - w_min) / (w_max - w_min) - 1 per axis (identity for None)."""
    if window is None:
        return points
    # per axis with Python constants: no host-to-device copies (sync-free on a GPU)
    return torch.stack(
        [2.0 * (points[:, a] - lo) / (hi - lo) - 1.0 for a, (lo, hi) in enumerate(window)],
        dim=-1,
    )


def _window_slope(window: Window | None) -> tuple[float, float, float]:
    """dq/dp per axis of :func:`_to_window`."""
    if window is None:
        return (1.0, 1.0, 1.0)
    return tuple(2.0 / (hi - lo) for lo, hi in window)  # type: ignore[return-value]


def _layout_groups(shapes, windows, planes) -> tuple[tuple[int, ...], ...]:
    """Levels that read the same rows with the same weights (equal true shapes, window,
    padded size and dtype: e.g. the geometry and appearance planes of one resolution),
    in order of their first level."""
    groups: dict[tuple, list[int]] = {}
    for level, (level_shapes, window, level_planes) in enumerate(
        zip(shapes, windows, planes, strict=True)
    ):
        key = (level_shapes, window, level_planes.shape[2:], level_planes.dtype)
        groups.setdefault(key, []).append(level)
    return tuple(tuple(group) for group in groups.values())


def _group_table(planes: Sequence[torch.Tensor], group: Sequence[int]) -> torch.Tensor:
    """(3 H W, sum C) the row tables of a group's levels side by side (a view for one)."""
    if len(group) == 1:
        return row_table(planes[group[0]])
    return torch.cat([row_table(planes[level]) for level in group], dim=1)


class FusedPlaneSampling(torch.autograd.Function):
    """Sum of the bilinear features of each level's three planes, all levels in one op.

    Inputs: the level shapes (a tuple of :data:`PlaneShapes`), the level windows (a
    tuple of :data:`Window` or None), the (N, 3) normalised points, then L plane tensors
    (3, C_l, H_l, W_l). Outputs: L tensors (N, C_l).

    Levels of one layout (:func:`_layout_groups`) share their look-ups: one set of rows
    and weights, one ``embedding_bag`` over their row tables side by side, one plane
    gradient and one coordinate gradient over their channels together.
    """

    @staticmethod
    def forward(ctx, shapes, windows, points: torch.Tensor, *planes: torch.Tensor):
        groups = _layout_groups(shapes, windows, planes)
        outputs: list[torch.Tensor | None] = [None] * len(planes)
        saved = []
        for group in groups:
            first = planes[group[0]]
            _, _, height, width = first.shape
            coords = _to_window(points.to(first.dtype), windows[group[0]])
            rows, weights, slopes = bilinear_corners(coords, shapes[group[0]], height, width)
            features = F.embedding_bag(
                rows, _group_table(planes, group), per_sample_weights=weights, mode="sum"
            )
            sizes = [planes[level].shape[1] for level in group]
            for level, part in zip(group, features.split(sizes, dim=1), strict=True):
                outputs[level] = part
            saved += [rows, weights, slopes]
        ctx.groups = groups
        ctx.windows = windows
        ctx.points_dtype = points.dtype
        ctx.save_for_backward(*planes, *saved)
        return tuple(outputs)

    @staticmethod
    @once_differentiable
    def backward(ctx, *grads: torch.Tensor):
        levels = len(ctx.windows)
        planes = ctx.saved_tensors[:levels]
        saved = ctx.saved_tensors[levels:]
        need_points, need_planes = ctx.needs_input_grad[2], ctx.needs_input_grad[3:]
        points_grad = None
        plane_grads: list[torch.Tensor | None] = [None] * levels
        for index, group in enumerate(ctx.groups):
            rows, weights, slopes = saved[3 * index : 3 * index + 3]
            grad = (
                grads[group[0]]
                if len(group) == 1
                else torch.cat([grads[level] for level in group], 1)
            )
            count_planes, _, height, width = planes[group[0]].shape
            if any(need_planes[level] for level in group):
                table = _plane_gradient(grad, rows, weights, (count_planes, height, width))
                sizes = [planes[level].shape[1] for level in group]
                for level, part in zip(group, table.split(sizes, dim=1), strict=True):
                    plane_grads[level] = part if need_planes[level] else None
            if need_points:
                coords_grad = _coordinate_gradient(grad, rows, slopes, _group_table(planes, group))
                window = ctx.windows[group[0]]
                if window is not None:
                    slope = _window_slope(window)
                    coords_grad = torch.stack(
                        [coords_grad[:, a] * slope[a] for a in range(3)], dim=-1
                    )
                points_grad = coords_grad if points_grad is None else points_grad + coords_grad
        if points_grad is not None:
            points_grad = points_grad.to(ctx.points_dtype)
        return (None, None, points_grad, *plane_grads)


def level_windows(planes: Sequence, shapes: Sequence, windows: Sequence | None) -> list:
    """The per-level windows (all None when ``windows`` is None), once the level lists are
    checked to have one entry per level.

    Raises:
        ValueError: no level, or lists of different lengths.
    """
    windows = [None] * len(planes) if windows is None else list(windows)
    if not (len(planes) == len(shapes) == len(windows)) or not planes:
        raise ValueError(
            f"need one plane tensor, shape and window per level, got "
            f"{len(planes)}, {len(shapes)} and {len(windows)}"
        )
    return windows


def sample_levels_fused(
    points: torch.Tensor,
    planes: Sequence[torch.Tensor],
    shapes: Sequence[PlaneShapes],
    windows: Sequence[Window | None] | None = None,
) -> tuple[torch.Tensor, ...]:
    """Per level, the (N, C) sum of its three planes' bilinear features, in one op.

    Args:
        points: (N, 3) the points in the scene's normalised coordinates.
        planes: per level, (3, C, H, W) padded planes, plane i in ``[i, :, :h_i, :w_i]``;
            channels-last storage makes the row table a view (otherwise it is copied).
        shapes: per level, the true (h, w) of its xy, xz and yz planes.
        windows: per level, its :data:`Window` (None: [-1, 1]; all None by default).

    Returns:
        One (N, C) tensor per level, equal to
        :func:`~eslam.field.plane_sampling.sample_planes_reference` of the level's coordinates.
    """
    windows = level_windows(planes, shapes, windows)
    layout = tuple(tuple(s) for s in shapes)
    return FusedPlaneSampling.apply(layout, tuple(windows), points, *planes)
