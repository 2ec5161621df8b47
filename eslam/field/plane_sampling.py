"""How plane features are read: the plane-sampling backends behind
``field.plane_sampling``, in one registry (:data:`PLANE_SAMPLINGS`).

A sampler reads one level's (N, C) features (:meth:`PlaneSampler.level`) and every
level of a field at once (:meth:`PlaneSampler.levels`); ``rows`` says whether it reads
rows of C features from channels-last planes (then every level of a field is sampled in
one op). The four (docs/method.md section 1; :mod:`eslam.field.planes`):

* reference: :func:`sample_planes_reference`, one ``grid_sample`` per plane (readable);
* fast: :func:`sample_planes_fast`, a level's three planes in one batched call;
* fused: :func:`~eslam.field.fused_sampling.sample_levels_fused`, every level in one op;
* triton: :func:`~eslam.field.triton_sampling.sample_levels_triton`, its kernels, for
  CUDA; its registry entry refuses other devices before a run starts.

tests/field/test_planes.py, test_fused_sampling.py and test_triton_sampling.py hold them
equal.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import torch
import torch.nn.functional as F

from eslam.config import FieldConfig
from eslam.field.fused_sampling import sample_levels_fused
from eslam.field.triton_sampling import check_device, sample_levels_triton
from eslam.registry import Registry

PLANE_AXES: tuple[tuple[int, int], ...] = ((0, 1), (0, 2), (1, 2))
"""Point coordinates (W axis, H axis) each plane of a level is sampled at: xy, xz, yz."""

PlaneShapes = tuple[tuple[int, int], ...]
"""The true (height, width) of the xy, xz and yz planes of a level."""


def _plane_coordinates(points_n: torch.Tensor) -> torch.Tensor:
    """(3, N, 2) the (W, H) grid coordinates of each plane of a level."""
    return torch.stack([points_n[:, axes] for axes in PLANE_AXES])


def sample_planes_reference(
    planes: torch.Tensor, shapes: PlaneShapes, points_n: torch.Tensor
) -> torch.Tensor:
    """Sum of the bilinear features of a level's three planes: one grid_sample per plane.

    The slow, readable reference of :func:`sample_planes_fast` (release semantics):
    bilinear, align_corners=True (p_n = -1 and +1 are the first and last vertex), border
    padding (points outside the bound read the border).

    Args:
        planes: (3, C, Hmax, Wmax) a level's padded planes; plane i is
            ``planes[i, :, :h_i, :w_i]``.
        shapes: the true (h_i, w_i) of the three planes.
        points_n: (N, 3) normalised coordinates.

    Returns:
        (N, C) the feature sum f_xy(x, y) + f_xz(x, z) + f_yz(y, z).
    """
    coords = _finite(_plane_coordinates(points_n))
    total = None
    for i, (h, w) in enumerate(shapes):
        plane = planes[i, :, :h, :w].unsqueeze(0)
        sampled = F.grid_sample(
            plane,
            coords[i].view(1, 1, -1, 2).to(plane.dtype),
            mode="bilinear",
            padding_mode="border",
            align_corners=True,
        )
        feature = sampled[0, :, 0, :].transpose(0, 1)
        total = feature if total is None else total + feature
    return total


class _MaskGradient(torch.autograd.Function):
    """Identity whose backward zeroes the gradient where ``padding`` is True."""

    @staticmethod
    def forward(ctx, tensor: torch.Tensor, padding: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(padding)
        return tensor.view_as(tensor)

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (padding,) = ctx.saved_tensors
        return grad.masked_fill(padding, 0), None


def _finite(coords: torch.Tensor) -> torch.Tensor:
    """NaN coordinates (a caller's bug) read the lower border: grid_sample on the CPU
    turns NaN into a memory index and crashes the process (a segfault) instead."""
    return torch.nan_to_num(coords, nan=-1.0)


def _clamp_border(coords: torch.Tensor) -> torch.Tensor:
    """Clamp to [-1, 1] with the gradient of grid_sample's border padding.

    grid_sample counts a coordinate ON the border as outside (zero gradient), while
    ``torch.clamp`` passes the gradient there; this matches grid_sample exactly.
    """
    inside = (coords > -1) & (coords < 1)
    return torch.where(inside, coords, coords.detach().clamp(-1.0, 1.0))


def padding_mask(shapes: PlaneShapes, height: int, width: int, device=None) -> torch.Tensor:
    """(3, 1, Hmax, Wmax) bool, True on the padding beyond each plane's true extent."""
    mask = torch.ones(3, 1, height, width, dtype=torch.bool, device=device)
    for i, (h, w) in enumerate(shapes):
        mask[i, :, :h, :w] = False
    return mask


def grid_scale(shapes: PlaneShapes, height: int, width: int, device=None) -> torch.Tensor:
    """(3, 1, 2) per plane ((w - 1) / (Wmax - 1), (h - 1) / (Hmax - 1)), float64.

    The factor that shrinks a plane's [-1, 1] onto its true extent inside the padded
    (Hmax, Wmax) tensor; 1 where the padded size is 1 (then the plane's size is 1 too).
    """
    rows = [
        [(w - 1) / (width - 1) if width > 1 else 1.0, (h - 1) / (height - 1) if height > 1 else 1.0]
        for h, w in shapes
    ]
    return torch.tensor(rows, dtype=torch.float64, device=device).view(3, 1, 2)


def sample_planes_fast(
    planes: torch.Tensor,
    shapes: PlaneShapes,
    points_n: torch.Tensor,
    padding: torch.Tensor | None = None,
    scale: torch.Tensor | None = None,
) -> torch.Tensor:
    """:func:`sample_planes_reference` in ONE batched grid_sample call (batch = 3 planes).

    Border padding with align_corners=True is a clamp of the coordinates to [-1, 1];
    then each plane's [-1, 1] is rescaled onto its true extent inside the padded tensor:
    g' = (g + 1) (w - 1) / (Wmax - 1) - 1, and the same along the height.

    Args:
        planes: (3, C, Hmax, Wmax) a level's padded planes.
        shapes: the true (h_i, w_i) of the three planes.
        points_n: (N, 3) normalised coordinates.
        padding: optional (3, 1, Hmax, Wmax) bool from :func:`padding_mask`; its entries
            get exactly zero gradient (without it, float rounding at the upper border can
            leak a ~1e-7 share of the gradient into the padding).
        scale: optional (3, 1, 2) from :func:`grid_scale` (computed when None).

    Returns:
        (N, C) the feature sum of the three planes.
    """
    if padding is not None and planes.requires_grad:
        planes = _MaskGradient.apply(planes, padding)
    if scale is None:
        scale = grid_scale(shapes, planes.shape[2], planes.shape[3], planes.device)
    scale = scale.to(planes.dtype)
    coords = _clamp_border(_finite(_plane_coordinates(points_n).to(planes.dtype)))
    grid = (coords + 1.0) * scale - 1.0
    sampled = F.grid_sample(
        planes, grid.unsqueeze(1), mode="bilinear", padding_mode="border", align_corners=True
    )
    return sampled.sum(dim=0)[:, 0, :].transpose(0, 1)


class PlaneSampler(Protocol):
    """Reads plane features of :class:`~eslam.field.planes.PlaneLevel` levels."""

    rows: bool
    """Channels-last planes, every level of a field read in one op."""

    def level(self, level: Any, points_n: torch.Tensor) -> torch.Tensor:
        """(N, C) features of one level at (N, 3) normalised scene points."""
        ...

    def levels(self, levels: Sequence[Any], points_n: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Each level's (N, C) features at (N, 3) normalised scene points."""
        ...


class _PerLevel:
    """A sampler that reads one level at a time (``reference``, ``fast``)."""

    rows = False

    def levels(self, levels: Sequence[Any], points_n: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return tuple(self.level(level, points_n) for level in levels)

    def level(self, level: Any, points_n: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError


class ReferenceSampler(_PerLevel):
    """``plane_sampling: reference`` (:func:`sample_planes_reference`)."""

    def level(self, level: Any, points_n: torch.Tensor) -> torch.Tensor:
        return sample_planes_reference(level.planes, level.shapes, level.coordinates(points_n))


class FastSampler(_PerLevel):
    """``plane_sampling: fast`` (:func:`sample_planes_fast`)."""

    def level(self, level: Any, points_n: torch.Tensor) -> torch.Tensor:
        coordinates = level.coordinates(points_n)
        return sample_planes_fast(
            level.planes, level.shapes, coordinates, level.padding, level.scale
        )


class _AllLevels:
    """A sampler that reads every level in one op from channels-last planes."""

    rows = True

    def level(self, level: Any, points_n: torch.Tensor) -> torch.Tensor:
        return self.levels([level], points_n)[0]

    def levels(self, levels: Sequence[Any], points_n: torch.Tensor) -> tuple[torch.Tensor, ...]:
        raise NotImplementedError


class FusedSampler(_AllLevels):
    """``plane_sampling: fused`` (:func:`~eslam.field.fused_sampling.sample_levels_fused`;
    each level's window as Python numbers, read once when it changes)."""

    def levels(self, levels: Sequence[Any], points_n: torch.Tensor) -> tuple[torch.Tensor, ...]:
        planes = [level.planes for level in levels]
        shapes = [level.shapes for level in levels]
        windows = [level._window_bounds for level in levels]
        return sample_levels_fused(points_n, planes, shapes, windows)


class TritonSampler(_AllLevels):
    """``plane_sampling: triton`` (:func:`~eslam.field.triton_sampling.sample_levels_triton`;
    the window buffers read on the device)."""

    def levels(self, levels: Sequence[Any], points_n: torch.Tensor) -> tuple[torch.Tensor, ...]:
        planes = [level.planes for level in levels]
        shapes = [level.shapes for level in levels]
        windows = [None if level._identity else level.window for level in levels]
        return sample_levels_triton(points_n, planes, shapes, windows)


def _triton_device(device: torch.device) -> None:
    check_device("triton", torch.device(device))


PLANE_SAMPLINGS: Registry[PlaneSampler] = Registry("plane sampling", "field.plane_sampling")
"""Plane samplers by ``field.plane_sampling``; a factory takes no argument."""
PLANE_SAMPLINGS.register("reference", ReferenceSampler, config=FieldConfig)
PLANE_SAMPLINGS.register("fast", FastSampler, config=FieldConfig)
PLANE_SAMPLINGS.register("fused", FusedSampler, config=FieldConfig)
PLANE_SAMPLINGS.register("triton", TritonSampler, config=FieldConfig, check=_triton_device)
