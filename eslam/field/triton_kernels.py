"""The Triton kernels of ``plane_sampling: triton`` (maths: :mod:`eslam.field.triton_sampling`).

Imported by :func:`eslam.field.triton_sampling.kernels` at the first use. ``@triton.jit``
reads ``TRITON_INTERPRET`` when it decorates, so these kernels run in Triton's CPU
interpreter when it is 1; it must be set before triton itself is imported (triton's own
library kernels, used by ``tl.sum``, are decorated then), which tests/conftest.py does
on a machine without CUDA.

One program handles ``BLOCK_POINTS`` points of ONE level (one launch per level): it
reads their 3 planes x 4 bilinear corners as (points, channels) tiles through the plane
tensor's strides (channels-last planes make each corner's C features one contiguous
read), so the padding beyond a plane's true size is never addressed.
"""

from __future__ import annotations

import triton
import triton.language as tl
from triton.runtime.interpreter import InterpretedFunction


@triton.jit
def _axis(q, count):
    """Cell, next vertex, fraction and slope d(vertex)/dq of one axis of ``count`` vertices
    at level coordinates ``q`` (:func:`eslam.field.fused_sampling.bilinear_corners`)."""
    span = count - 1
    q = tl.where(q != q, -1.0, q)  # NaN reads the lower border (nan_to_num in the op)
    # +-inf: beyond the border like any |q| > 1 (clamped below, slope 0); avoids inf * 0
    q = tl.minimum(tl.maximum(q, -2.0), 2.0)
    position = (q + 1) / 2 * span
    slope = tl.where((position > 0) & (position < span), span / 2, 0.0)
    position = tl.minimum(tl.maximum(position, 0.0), span * 1.0).to(q.dtype)
    cell = tl.minimum(tl.floor(position), tl.maximum(span - 1, 0) * 1.0).to(q.dtype)
    fraction = position - cell
    first = cell.to(tl.int32)
    return first, tl.minimum(first + 1, span), fraction, slope.to(q.dtype)


@triton.jit
def _level_coordinate(
    points, window, planes, n, inside, axis, stride_point, stride_axis, HAS_WINDOW
):
    """The level coordinate q of axis ``axis`` of points ``n`` in the planes' dtype:
    2 (p - lo) / (hi - lo) - 1 with a window ((3, 2) contiguous), p without."""
    p = tl.load(points + n * stride_point + axis * stride_axis, mask=inside, other=0.0)
    p = p.to(planes.dtype.element_ty)
    if HAS_WINDOW:
        lo = tl.load(window + 2 * axis).to(p.dtype)
        hi = tl.load(window + 2 * axis + 1).to(p.dtype)
        p = 2.0 * (p - lo) / (hi - lo) - 1.0
    return p


@triton.jit
def _window_slope(window, planes, axis):
    """dq/dp of :func:`_level_coordinate` with a window: 2 / (hi - lo)."""
    lo = tl.load(window + 2 * axis).to(planes.dtype.element_ty)
    hi = tl.load(window + 2 * axis + 1).to(planes.dtype.element_ty)
    return 2.0 / (hi - lo)


@triton.jit
def _point_axes(
    points, window, planes, n, inside, nx, ny, nz, stride_point, stride_axis, HAS_WINDOW
):
    """:func:`_axis` of the x, y and z coordinates of points ``n``."""
    x = _axis(
        _level_coordinate(
            points, window, planes, n, inside, 0, stride_point, stride_axis, HAS_WINDOW
        ),
        nx,
    )
    y = _axis(
        _level_coordinate(
            points, window, planes, n, inside, 1, stride_point, stride_axis, HAS_WINDOW
        ),
        ny,
    )
    z = _axis(
        _level_coordinate(
            points, window, planes, n, inside, 2, stride_point, stride_axis, HAS_WINDOW
        ),
        nz,
    )
    return x, y, z


@triton.jit
def _corner_offsets(plane, u0, u1, v0, v1, stride_row, stride_col):
    """Element offsets (points, 1) of a plane's corners (v0, u0), (v0, u1), (v1, u0),
    (v1, u1) (row v, column u; the order of fused_sampling.CORNERS), ``plane`` being the
    offset of the plane's (0, 0)."""
    o00 = plane + v0 * stride_row + u0 * stride_col
    o01 = plane + v0 * stride_row + u1 * stride_col
    o10 = plane + v1 * stride_row + u0 * stride_col
    o11 = plane + v1 * stride_row + u1 * stride_col
    return o00[:, None], o01[:, None], o10[:, None], o11[:, None]


@triton.jit
def sample_level_kernel(
    points,
    window,
    planes,
    out,
    n_points,
    channels,
    nx,
    ny,
    nz,
    stride_point,
    stride_axis,
    stride_plane,
    stride_channel,
    stride_row,
    stride_col,
    stride_out_point,
    stride_out_channel,
    HAS_WINDOW: tl.constexpr,
    BLOCK_POINTS: tl.constexpr,
    BLOCK_CHANNELS: tl.constexpr,
):
    """out[n] = sum over the xy, xz, yz planes of the bilinear sum of 4 corner rows."""
    n = tl.program_id(0) * BLOCK_POINTS + tl.arange(0, BLOCK_POINTS)
    inside = n < n_points
    c = tl.arange(0, BLOCK_CHANNELS)
    mask = inside[:, None] & (c < channels)[None, :]
    feature_offsets = (c * stride_channel)[None, :]
    (x0, x1, fx, _), (y0, y1, fy, _), (z0, z1, fz, _) = _point_axes(
        points, window, planes, n, inside, nx, ny, nz, stride_point, stride_axis, HAS_WINDOW
    )
    total = tl.zeros((BLOCK_POINTS, BLOCK_CHANNELS), dtype=fx.dtype)
    # planes xy, xz, yz read (u, v) = (x, y), (x, z), (y, z)
    for i in tl.static_range(3):
        if i == 0:
            u0, u1, fu, v0, v1, fv = x0, x1, fx, y0, y1, fy
        elif i == 1:
            u0, u1, fu, v0, v1, fv = x0, x1, fx, z0, z1, fz
        else:
            u0, u1, fu, v0, v1, fv = y0, y1, fy, z0, z1, fz
        o00, o01, o10, o11 = _corner_offsets(
            i * stride_plane, u0, u1, v0, v1, stride_row, stride_col
        )
        eu, ev = (1 - fu)[:, None], (1 - fv)[:, None]
        gu, gv = fu[:, None], fv[:, None]
        total += ev * eu * tl.load(planes + o00 + feature_offsets, mask=mask, other=0.0)
        total += ev * gu * tl.load(planes + o01 + feature_offsets, mask=mask, other=0.0)
        total += gv * eu * tl.load(planes + o10 + feature_offsets, mask=mask, other=0.0)
        total += gv * gu * tl.load(planes + o11 + feature_offsets, mask=mask, other=0.0)
    tl.store(
        out + (n * stride_out_point)[:, None] + (c * stride_out_channel)[None, :], total, mask=mask
    )


@triton.jit
def sample_level_backward_kernel(
    grad,
    points,
    window,
    planes,
    grad_planes,
    grad_points,
    n_points,
    channels,
    nx,
    ny,
    nz,
    stride_grad_point,
    stride_grad_channel,
    stride_point,
    stride_axis,
    stride_plane,
    stride_channel,
    stride_row,
    stride_col,
    NEED_PLANES: tl.constexpr,
    NEED_POINTS: tl.constexpr,
    HAS_WINDOW: tl.constexpr,
    BLOCK_POINTS: tl.constexpr,
    BLOCK_CHANNELS: tl.constexpr,
):
    """Plane gradients (atomic adds of w g into the corners; ``grad_planes`` has the
    planes' strides) and coordinate gradients (ADDED into ``grad_points`` (N, 3),
    contiguous, the planes' dtype: one launch per level adds that level's share)."""
    n = tl.program_id(0) * BLOCK_POINTS + tl.arange(0, BLOCK_POINTS)
    inside = n < n_points
    c = tl.arange(0, BLOCK_CHANNELS)
    mask = inside[:, None] & (c < channels)[None, :]
    feature_offsets = (c * stride_channel)[None, :]
    g = tl.load(
        grad + (n * stride_grad_point)[:, None] + (c * stride_grad_channel)[None, :],
        mask=mask,
        other=0.0,
    ).to(planes.dtype.element_ty)
    (x0, x1, fx, sx), (y0, y1, fy, sy), (z0, z1, fz, sz) = _point_axes(
        points, window, planes, n, inside, nx, ny, nz, stride_point, stride_axis, HAS_WINDOW
    )
    gx = tl.zeros((BLOCK_POINTS,), dtype=fx.dtype)
    gy = tl.zeros((BLOCK_POINTS,), dtype=fx.dtype)
    gz = tl.zeros((BLOCK_POINTS,), dtype=fx.dtype)
    for i in tl.static_range(3):
        if i == 0:
            u0, u1, fu, su, v0, v1, fv, sv = x0, x1, fx, sx, y0, y1, fy, sy
        elif i == 1:
            u0, u1, fu, su, v0, v1, fv, sv = x0, x1, fx, sx, z0, z1, fz, sz
        else:
            u0, u1, fu, su, v0, v1, fv, sv = y0, y1, fy, sy, z0, z1, fz, sz
        o00, o01, o10, o11 = _corner_offsets(
            i * stride_plane, u0, u1, v0, v1, stride_row, stride_col
        )
        if NEED_PLANES:
            eu, ev = (1 - fu)[:, None], (1 - fv)[:, None]
            gu, gv = fu[:, None], fv[:, None]
            tl.atomic_add(grad_planes + o00 + feature_offsets, ev * eu * g, mask=mask)
            tl.atomic_add(grad_planes + o01 + feature_offsets, ev * gu * g, mask=mask)
            tl.atomic_add(grad_planes + o10 + feature_offsets, gv * eu * g, mask=mask)
            tl.atomic_add(grad_planes + o11 + feature_offsets, gv * gu * g, mask=mask)
        if NEED_POINTS:
            # d_k = <P[r_k], g>; df/dfu, df/dfv times the vertex slopes (0 on the border)
            d00 = tl.sum(tl.load(planes + o00 + feature_offsets, mask=mask, other=0.0) * g, 1)
            d01 = tl.sum(tl.load(planes + o01 + feature_offsets, mask=mask, other=0.0) * g, 1)
            d10 = tl.sum(tl.load(planes + o10 + feature_offsets, mask=mask, other=0.0) * g, 1)
            d11 = tl.sum(tl.load(planes + o11 + feature_offsets, mask=mask, other=0.0) * g, 1)
            du = ((1 - fv) * (d01 - d00) + fv * (d11 - d10)) * su
            dv = ((1 - fu) * (d10 - d00) + fu * (d11 - d01)) * sv
            if i == 0:
                gx += du
                gy += dv
            elif i == 1:
                gx += du
                gz += dv
            else:
                gy += du
                gz += dv
    if NEED_POINTS:
        if HAS_WINDOW:
            gx = gx * _window_slope(window, planes, 0)
            gy = gy * _window_slope(window, planes, 1)
            gz = gz * _window_slope(window, planes, 2)
        row = grad_points + n * 3
        tl.store(row, tl.load(row, mask=inside) + gx, mask=inside)
        tl.store(row + 1, tl.load(row + 1, mask=inside) + gy, mask=inside)
        tl.store(row + 2, tl.load(row + 2, mask=inside) + gz, mask=inside)


INTERPRETED = isinstance(sample_level_kernel, InterpretedFunction)
"""Whether these kernels run in Triton's CPU interpreter (``TRITON_INTERPRET=1`` at import)."""
