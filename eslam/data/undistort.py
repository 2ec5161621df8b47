"""Lens distortion in OpenCV's plumb-bob model, and image undistortion in numpy.

The model (OpenCV's ``distortion_coefficients`` (k1, k2, p1, p2, k3), also TUM RGB-D's
calibration format) maps an ideal normalised image point (x, y) = ((u - cx) / fx,
(v - cy) / fy) to the distorted point the lens images it at::

    r2 = x^2 + y^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
    yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

Undistorting an image works backwards, as ``cv2.undistort`` does: every pixel of the
output (ideal pinhole image, same K as the input) takes the value found at its
distorted position in the input. Colour is sampled bilinearly; depth with nearest
neighbour, so no depth is ever blended across an edge and invalid (0) stays invalid.
Positions outside the input give 0 (black colour, invalid depth), like OpenCV's
constant border. No OpenCV dependency: everything here is numpy.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eslam.types import Intrinsics

INVERSE_ITERATIONS = 100
"""Most fixed-point steps of :meth:`PlumbBob.undistort` (it stops earlier once converged)."""
INVERSE_TOLERANCE = 1e-12
"""Largest change of a normalised coordinate at which the inversion has converged."""
_OUTSIDE = -2.0
"""Sample position used for non-finite coordinates: outside every image."""


@dataclass(frozen=True)
class PlumbBob:
    """OpenCV's radial-tangential distortion coefficients (dimensionless).

    Attributes:
        k1: first radial coefficient.
        k2: second radial coefficient.
        p1: first tangential coefficient.
        p2: second tangential coefficient.
        k3: third radial coefficient.
    """

    k1: float
    k2: float
    p1: float
    p2: float
    k3: float = 0.0

    @property
    def is_identity(self) -> bool:
        """True when every coefficient is 0 (no distortion)."""
        return not any((self.k1, self.k2, self.p1, self.p2, self.k3))

    def distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distorted normalised coordinates of ideal normalised points (the forward model).

        Args:
            x: (...) ideal normalised x = (u - cx) / fx.
            y: (...) ideal normalised y = (v - cy) / fy.

        Returns:
            xd, yd: (...) distorted normalised coordinates.
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xd = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x)
        yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y
        return xd, yd

    def undistort(self, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalised coordinates of distorted ones (inverse of :meth:`distort`).

        Fixed-point iteration x <- (xd - tangential(x, y)) / radial(x, y), as
        ``cv2.undistortPoints``, run until no coordinate moves by more than
        INVERSE_TOLERANCE (at most INVERSE_ITERATIONS steps). It converges inside the
        image of the TUM cameras; points where it does not are returned as NaN.

        Args:
            xd: (...) distorted normalised x.
            yd: (...) distorted normalised y.

        Returns:
            x, y: (...) ideal normalised coordinates (NaN where the iteration diverged).
        """
        xd = np.asarray(xd, dtype=np.float64)
        yd = np.asarray(yd, dtype=np.float64)
        x, y = xd.copy(), yd.copy()
        for _ in range(INVERSE_ITERATIONS):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
            dx = 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x)
            dy = self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                x_next, y_next = (xd - dx) / radial, (yd - dy) / radial
                change = np.maximum(np.abs(x_next - x), np.abs(y_next - y))
            x, y = x_next, y_next
            if not np.any(change > INVERSE_TOLERANCE):
                break
        with np.errstate(invalid="ignore", over="ignore"):
            check_x, check_y = self.distort(x, y)
            error = np.maximum(np.abs(check_x - xd), np.abs(check_y - yd))
        failed = ~(error <= 1e3 * INVERSE_TOLERANCE)
        return np.where(failed, np.nan, x), np.where(failed, np.nan, y)


def _pixel_grid(intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) normalised x and y of every pixel centre of ``intrinsics``."""
    u = (np.arange(intrinsics.width, dtype=np.float64) - intrinsics.cx) / intrinsics.fx
    v = (np.arange(intrinsics.height, dtype=np.float64) - intrinsics.cy) / intrinsics.fy
    return np.meshgrid(u, v, indexing="xy")


def _to_pixels(x: np.ndarray, y: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    return np.stack([intrinsics.fx * x + intrinsics.cx, intrinsics.fy * y + intrinsics.cy], -1)


def undistort_map(intrinsics: Intrinsics, distortion: PlumbBob) -> np.ndarray:
    """Where each pixel of the undistorted image is found in the distorted image.

    The undistorted image keeps the same size and K (as ``cv2.undistort``).

    Returns:
        (H, W, 2) float64 pixel coordinates (u, v) in the distorted input image.
    """
    x, y = _pixel_grid(intrinsics)
    return _to_pixels(*distortion.distort(x, y), intrinsics)


def distort_map(intrinsics: Intrinsics, distortion: PlumbBob) -> np.ndarray:
    """Where each pixel of a distorted image is found in the ideal (undistorted) image.

    The inverse of :func:`undistort_map`; used to simulate a distorting lens.

    Returns:
        (H, W, 2) float64 pixel coordinates (u, v) in the undistorted image (NaN where
        the inversion fails; sampling treats NaN as outside).
    """
    xd, yd = _pixel_grid(intrinsics)
    return _to_pixels(*distortion.undistort(xd, yd), intrinsics)


@dataclass(frozen=True, eq=False)
class SamplePlan:
    """Precomputed lookups that sample (H, W) images at fixed positions, 0 outside.

    Images are padded with a 1-pixel border of zeros and flattened; every position
    outside the image is clamped into that border, so one ``np.take`` per neighbour
    does the sampling.

    Attributes:
        source_size: (width, height) of the images sampled.
        out_shape: (H', W') of the result.
        bilinear_index: (4, H' W') flat indices of the four neighbours in the padded image.
        bilinear_weight: (4, H' W') float32 bilinear weights (sum to 1).
        nearest_index: (H' W',) flat index of the nearest pixel in the padded image.
    """

    source_size: tuple[int, int]
    out_shape: tuple[int, int]
    bilinear_index: np.ndarray
    bilinear_weight: np.ndarray
    nearest_index: np.ndarray


def sample_plan(coords: np.ndarray, source_size: tuple[int, int]) -> SamplePlan:
    """The :class:`SamplePlan` sampling images of ``source_size`` at ``coords``.

    Args:
        coords: (H', W', 2) pixel coordinates (u, v) to sample, pixel centres at integers.
        source_size: (width, height) of the images to sample.
    """
    width, height = source_size
    u = np.where(np.isfinite(coords[..., 0]), coords[..., 0], _OUTSIDE).reshape(-1)
    v = np.where(np.isfinite(coords[..., 1]), coords[..., 1], _OUTSIDE).reshape(-1)

    def flat(ui: np.ndarray, vi: np.ndarray) -> np.ndarray:
        # padded image: pixel (u, v) sits at (u + 1, v + 1); everything outside -> border
        return np.clip(vi + 1, 0, height + 1) * (width + 2) + np.clip(ui + 1, 0, width + 1)

    u = np.clip(u, -1.5, width + 0.5)
    v = np.clip(v, -1.5, height + 0.5)
    u0, v0 = np.floor(u), np.floor(v)
    fu, fv = u - u0, v - v0
    u0, v0 = u0.astype(np.int64), v0.astype(np.int64)
    index = np.stack([flat(u0, v0), flat(u0 + 1, v0), flat(u0, v0 + 1), flat(u0 + 1, v0 + 1)])
    weight = np.stack([(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv])
    nearest = flat(np.floor(u + 0.5).astype(np.int64), np.floor(v + 0.5).astype(np.int64))
    return SamplePlan((width, height), coords.shape[:2], index, weight.astype(np.float32), nearest)


def _padded_flat(image: np.ndarray, plan: SamplePlan) -> np.ndarray:
    if (image.shape[1], image.shape[0]) != plan.source_size:
        raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, plan for {plan.source_size}")
    pad = ((1, 1), (1, 1)) + ((0, 0),) * (image.ndim - 2)
    return np.pad(image, pad).reshape(-1, *image.shape[2:])


def apply_bilinear(image: np.ndarray, plan: SamplePlan) -> np.ndarray:
    """Bilinear samples of ``image`` (H, W[, C]) at the plan's positions; uint8 is rounded."""
    flat = _padded_flat(image, plan).astype(np.float32)
    weight = plan.bilinear_weight if image.ndim == 2 else plan.bilinear_weight[..., None]
    result = sum(np.take(flat, plan.bilinear_index[k], axis=0) * weight[k] for k in range(4))
    result = result.reshape(*plan.out_shape, *image.shape[2:])
    if image.dtype == np.uint8:
        return np.clip(np.rint(result), 0, 255).astype(np.uint8)
    return result.astype(image.dtype)


def apply_nearest(image: np.ndarray, plan: SamplePlan) -> np.ndarray:
    """Nearest-pixel samples of ``image`` (H, W[, C]) at the plan's positions; 0 outside."""
    flat = _padded_flat(image, plan)
    return np.take(flat, plan.nearest_index, axis=0).reshape(*plan.out_shape, *image.shape[2:])


def remap_bilinear(image: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Sample ``image`` bilinearly at ``coords``; neighbours outside the image count as 0.

    Args:
        image: (H, W) or (H, W, C) image; uint8 images are rounded back to uint8.
        coords: (H', W', 2) pixel coordinates (u, v) to sample, pixel centres at integers.

    Returns:
        (H', W') or (H', W', C) image of the dtype of ``image``.
    """
    return apply_bilinear(image, sample_plan(coords, (image.shape[1], image.shape[0])))


def remap_nearest(image: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Sample ``image`` at the pixel nearest to each of ``coords``; 0 outside the image.

    Args:
        image: (H, W) or (H, W, C) image.
        coords: (H', W', 2) pixel coordinates (u, v), pixel centres at integers.

    Returns:
        (H', W') or (H', W', C) image of the dtype of ``image``.
    """
    return apply_nearest(image, sample_plan(coords, (image.shape[1], image.shape[0])))


@dataclass(frozen=True, eq=False)
class Undistorter:
    """Undistorts colour and depth images of one camera (the sample map is computed once).

    Attributes:
        intrinsics: the camera (input and output share it, as in ``cv2.undistort``).
        distortion: its plumb-bob coefficients.
    """

    intrinsics: Intrinsics
    distortion: PlumbBob
    _plan: SamplePlan = field(init=False, repr=False)

    def __post_init__(self) -> None:
        coords = undistort_map(self.intrinsics, self.distortion)
        object.__setattr__(self, "_plan", sample_plan(coords, self.intrinsics.size))

    def colour(self, rgb: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 distorted -> (H, W, 3) uint8 undistorted (bilinear, black outside)."""
        return apply_bilinear(rgb, self._plan)

    def depth(self, depth: np.ndarray) -> np.ndarray:
        """(H, W) float32 metres -> (H, W) float32 metres (nearest, 0 = invalid outside)."""
        return apply_nearest(depth, self._plan)

    def images(self, rgb: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both images of a registered pair: (:meth:`colour`, :meth:`depth`)."""
        return self.colour(rgb), self.depth(depth)
