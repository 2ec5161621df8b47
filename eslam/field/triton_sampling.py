"""Every plane level sampled by Triton kernels (``plane_sampling: triton``, for CUDA).

The same maths as :mod:`eslam.field.fused_sampling` (its docstring and
:func:`~eslam.field.fused_sampling.bilinear_corners`), which equals the reference
:func:`eslam.field.plane_sampling.sample_planes_reference` (``grid_sample``, align_corners=True,
border padding). Per level, with window (lo, hi) per axis (none: q = p),

    q = 2 (p - lo) / (hi - lo) - 1                    (NaN -> -1, as the reference)
    x = clamp((q_x + 1) / 2 (nx - 1), 0, nx - 1),  x0 = min(floor(x), nx - 2),  fx = x - x0
    f = sum over planes (u, v) in {(x, y), (x, z), (y, z)} of
        (1-fu)(1-fv) P[v0, u0] + fu (1-fv) P[v0, u1] + (1-fu) fv P[v1, u0] + fu fv P[v1, u1]

with u1 = min(u0 + 1, nu - 1) (y, z alike). Backward, for output gradients g (N, C):

* planes: dL/dP[v, u] += w g_n for each of the point's 12 (corner, weight w) pairs,
  ``tl.atomic_add`` into a zero tensor with the planes' strides; the padding beyond a
  plane's true size is never addressed, so its gradient is exactly zero;
* coordinates: with d_k = <P[corner k], g_n>,
  df/dfu = (1-fv)(d01 - d00) + fv (d11 - d10),  df/dfv = (1-fu)(d10 - d00) + fu (d11 - d01),
  times dx/dq = (nx - 1) / 2 strictly inside the grid and 0 on or beyond its border
  (grid_sample's border-padding gradient), times dq/dp = 2 / (hi - lo); summed over the
  planes that read the axis and over the levels.

Kernels (:mod:`eslam.field.triton_kernels`): ONE LAUNCH PER LEVEL (levels differ in
channels and plane sizes), one program per block of :data:`BLOCK_POINTS` points reading
(points, channels) tiles; the backward launch computes both gradients of a level at once
(each only when asked for) and adds the level's coordinate gradient into one (N, 3)
buffer. Window tensors (the levels' (3, 2) buffers) are read on the device, in the
planes' dtype: no host-device copy or sync.

Operators: ``eslam::sample_planes`` and ``eslam::sample_planes_backward``
(``torch.library.custom_op`` with ``register_fake`` and ``register_autograd``), so
``torch.compile`` traces a call as one opaque op (fake tensors give its shapes) and
AOTAutograd traces its backward as the second op. Double backward raises (no second
derivatives: the SDF tracker and mapping need first ones only).

Availability: the ops are defined only where ``import triton`` works and torch has
``torch.library.custom_op`` (torch >= 2.4; the package accepts torch >= 2.3); otherwise
:func:`sample_levels_triton` raises one RuntimeError naming the fix. The kernels run on
CUDA tensors, or on CPU tensors in Triton's interpreter when ``TRITON_INTERPRET=1`` is
in the process's environment before triton is imported (triton decorates its own
library kernels, tl.sum's among them, at import; setting it later fails inside the
interpreter). The interpreter is slow: for tests. tests/field/test_triton_sampling.py holds
values and both gradients to the reference in the interpreter (float64 and float32) and,
on a machine with CUDA, the compiled kernels; this module was written on a CPU-only
machine and its compiled kernels have not run on a GPU here.
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Sequence
from types import ModuleType

import torch

from eslam.errors import ConfigError
from eslam.field.fused_sampling import PlaneShapes, level_grid, level_windows

try:
    import triton
except ImportError:  # the op is then undefined and using it raises (unavailable_reason)
    triton = None

BLOCK_POINTS = 32
"""Points per program on a GPU: (32, C) corner tiles, with :data:`NUM_WARPS`. Not timed
(no GPU was at hand): chosen by ptxas's register report for sm_90 and C = 32
(benchmarks/triton_ptxas.py; docs/benchmarks.md, "Triton plane-sampling kernels"), the
largest block that spills in neither kernel nor dtype at 8 warps."""

NUM_WARPS = 8
"""Warps per program: at Triton's default 4 every kernel variant used 198-255
registers per thread and spilled from 32 points on (the backward) in the same report."""

BLOCK_POINTS_INTERPRETED = 128
"""Points per program in Triton's interpreter, which runs programs one after another
(a numpy pass each): fewer, larger blocks are what make its tests fast."""

FLOAT_TYPES = (torch.float32, torch.float64)
"""Plane dtypes the kernels accept (the field's float32; float64 for the tests)."""


def unavailable_reason() -> str | None:
    """Why the Triton ops cannot be used in this environment, or None when they can."""
    if triton is None:
        return "needs the triton package (pip install triton; CUDA builds of torch bring it)"
    if not hasattr(torch.library, "custom_op"):
        return f"needs torch >= 2.4 for torch.library.custom_op (this is {torch.__version__})"
    return None


def kernels() -> ModuleType:
    """The kernels module (imported at the first use; ``INTERPRETED`` says whether its
    kernels run in Triton's CPU interpreter)."""
    return importlib.import_module("eslam.field.triton_kernels")


def check_device(sampling: str, device: torch.device) -> None:
    """Refuse ``plane_sampling: triton`` where it cannot run, before a run starts.

    Raises:
        ConfigError: triton is missing, or ``device`` is not CUDA (a CPU is accepted
            only when the kernels run in Triton's interpreter, TRITON_INTERPRET=1).
    """
    if sampling != "triton":
        return
    problem = unavailable_reason()
    if problem is not None:
        raise ConfigError(f"field.plane_sampling: triton {problem} (or use fused)")
    if device.type == "cuda" or (device.type == "cpu" and kernels().INTERPRETED):
        return
    raise ConfigError(
        f"field.plane_sampling: triton runs on CUDA, not on the {device.type} device "
        "(use plane_sampling: fused, or a cuda device; TRITON_INTERPRET=1 runs Triton's "
        "slow CPU interpreter)"
    )


def _launch_context(points: torch.Tensor, module: ModuleType):
    """The device the kernels launch on (the points'), after checking they can."""
    if points.device.type == "cuda":
        return torch.cuda.device(points.device)
    if not module.INTERPRETED:
        raise RuntimeError(
            f"the Triton plane-sampling kernels run on CUDA tensors, got {points.device} "
            "ones (use plane_sampling: fused, or start the process with TRITON_INTERPRET=1 "
            "for Triton's CPU interpreter)"
        )
    return contextlib.nullcontext()


def _launch(module: ModuleType, points: torch.Tensor, planes: torch.Tensor):
    """Launch grid, block sizes and warps of one level's kernel."""
    block = BLOCK_POINTS_INTERPRETED if module.INTERPRETED else BLOCK_POINTS
    grid = (triton.cdiv(points.shape[0], block),)
    options = dict(
        BLOCK_POINTS=block,
        BLOCK_CHANNELS=triton.next_power_of_2(planes.shape[1]),
        num_warps=NUM_WARPS,  # a launch option (the interpreter ignores it)
    )
    return grid, options


def _forward(
    points: torch.Tensor,
    planes: list[torch.Tensor],
    windows: list[torch.Tensor],
    grids: list[int],
) -> list[torch.Tensor]:
    """Per level, the (N, C) features (one kernel launch per level)."""
    module = kernels()
    outputs = []
    with _launch_context(points, module):
        for level, (level_planes, window) in enumerate(zip(planes, windows, strict=True)):
            count = points.shape[0]
            out = torch.empty(
                count, level_planes.shape[1], dtype=level_planes.dtype, device=points.device
            )
            outputs.append(out)
            if count == 0:
                continue
            grid, blocks = _launch(module, points, level_planes)
            framed = window.numel() > 0
            module.sample_level_kernel[grid](
                points,
                window if framed else points,  # not read without a window
                level_planes,
                out,
                count,
                level_planes.shape[1],
                *grids[3 * level : 3 * level + 3],
                *points.stride(),
                *level_planes.stride(),
                *out.stride(),
                HAS_WINDOW=framed,
                **blocks,
            )
    return outputs


def _backward(
    grads: list[torch.Tensor],
    points: torch.Tensor,
    planes: list[torch.Tensor],
    windows: list[torch.Tensor],
    grids: list[int],
    need_points: bool,
    need_planes: list[bool],
) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """dL/dpoints (N, 3) (empty unless ``need_points``) and per level dL/dplanes (empty
    unless asked for), one kernel launch per level."""
    module = kernels()
    count = points.shape[0]
    dtype = planes[0].dtype
    grad_points = torch.zeros(count if need_points else 0, 3, dtype=dtype, device=points.device)
    grad_planes = []
    with _launch_context(points, module):
        for level, (level_planes, window) in enumerate(zip(planes, windows, strict=True)):
            need = need_planes[level]
            grad = torch.zeros_like(level_planes) if need else level_planes.new_empty(0)
            grad_planes.append(grad)
            if count == 0 or not (need or need_points):
                continue
            if need and grad.stride() != level_planes.stride():
                raise AssertionError("plane gradients must have the planes' strides")
            grid, blocks = _launch(module, points, level_planes)
            framed = window.numel() > 0
            module.sample_level_backward_kernel[grid](
                grads[level],
                points,
                window if framed else points,
                level_planes,
                grad if need else level_planes,  # not written unless asked for
                grad_points if need_points else points,
                count,
                level_planes.shape[1],
                *grids[3 * level : 3 * level + 3],
                *grads[level].stride(),
                *points.stride(),
                *level_planes.stride(),
                NEED_PLANES=need,
                NEED_POINTS=need_points,
                HAS_WINDOW=framed,
                **blocks,
            )
    return grad_points.to(points.dtype), grad_planes


if unavailable_reason() is None:

    @torch.library.custom_op("eslam::sample_planes", mutates_args=())
    def _sample_planes_op(
        points: torch.Tensor,
        planes: list[torch.Tensor],
        windows: list[torch.Tensor],
        grids: list[int],
    ) -> list[torch.Tensor]:
        return _forward(points, planes, windows, grids)

    @_sample_planes_op.register_fake
    def _(points, planes, windows, grids):
        return [p.new_empty(points.shape[0], p.shape[1]) for p in planes]

    @torch.library.custom_op("eslam::sample_planes_backward", mutates_args=())
    def _sample_planes_backward_op(
        grads: list[torch.Tensor],
        points: torch.Tensor,
        planes: list[torch.Tensor],
        windows: list[torch.Tensor],
        grids: list[int],
        need_points: bool,
        need_planes: list[bool],
    ) -> tuple[torch.Tensor, list[torch.Tensor]]:
        return _backward(grads, points, planes, windows, grids, need_points, need_planes)

    @_sample_planes_backward_op.register_fake
    def _(grads, points, planes, windows, grids, need_points, need_planes):
        grad_points = points.new_empty(points.shape[0] if need_points else 0, 3)
        return grad_points, [
            torch.empty_like(p) if need else p.new_empty(0)
            for p, need in zip(planes, need_planes, strict=True)
        ]

    def _setup_context(ctx, inputs, output) -> None:
        points, planes, windows, grids = inputs
        ctx.save_for_backward(points, *planes, *windows)
        ctx.levels, ctx.grids = len(planes), list(grids)

    def _sample_planes_grad(ctx, grads):
        levels = ctx.levels
        points, *saved = ctx.saved_tensors
        planes, windows = saved[:levels], saved[levels:]
        need_points, need_planes = ctx.needs_input_grad[0], list(ctx.needs_input_grad[1])
        grad_points, grad_planes = torch.ops.eslam.sample_planes_backward(
            list(grads), points, list(planes), list(windows), ctx.grids, need_points, need_planes
        )
        return (
            grad_points if need_points else None,
            [g if need else None for g, need in zip(grad_planes, need_planes, strict=True)],
            [None] * levels,
            None,
        )

    _sample_planes_op.register_autograd(_sample_planes_grad, setup_context=_setup_context)


def sample_levels_triton(
    points: torch.Tensor,
    planes: Sequence[torch.Tensor],
    shapes: Sequence[PlaneShapes],
    windows: Sequence[torch.Tensor | None] | None = None,
) -> tuple[torch.Tensor, ...]:
    """Per level, the (N, C) sum of its three planes' bilinear features (Triton kernels).

    Args:
        points: (N, 3) the points in the scene's normalised coordinates.
        planes: per level, (3, C, H, W) padded planes (float32 or float64, one dtype),
            plane i in ``[i, :, :h_i, :w_i]``; channels-last storage makes each corner's
            C features one contiguous read (any strides work).
        shapes: per level, the true (h, w) of its xy, xz and yz planes.
        windows: per level, its (3, 2) window tensor on the points' device (the level's
            ``window`` buffer), or None for [-1, 1] (all None by default).

    Returns:
        One (N, C) tensor per level, equal to
        :func:`~eslam.field.plane_sampling.sample_planes_reference` of the level's coordinates.

    Raises:
        RuntimeError: triton or torch.library.custom_op missing (the message names the
            fix), or CPU tensors without TRITON_INTERPRET=1.
        ValueError: mismatched level lists, dtypes, or planes smaller than their shapes.
    """
    problem = unavailable_reason()
    if problem is not None:
        raise RuntimeError(f"plane_sampling: triton {problem}; use plane_sampling: fused")
    windows = level_windows(planes, shapes, windows)
    grids: list[int] = []
    for level_planes, level_shapes in zip(planes, shapes, strict=True):
        if level_planes.dtype not in FLOAT_TYPES or level_planes.dtype != planes[0].dtype:
            raise ValueError(f"planes must all be float32 or all float64, got {level_planes.dtype}")
        height, width = level_planes.shape[2:]
        if any(h > height or w > width for h, w in level_shapes):
            raise ValueError(f"plane shapes {level_shapes} exceed the planes' {height}x{width}")
        grids += level_grid(tuple(tuple(s) for s in level_shapes))  # type: ignore[arg-type]
    frames = [points.new_empty(0) if window is None else window.contiguous() for window in windows]
    return tuple(torch.ops.eslam.sample_planes(points, list(planes), frames, grids))
