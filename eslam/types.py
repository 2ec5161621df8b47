"""Small frozen values passed between layers.

Conventions (see ARCHITECTURE.md): poses are camera-to-world 4x4 matrices in OpenCV
camera axes (x right, y down, z forward), metres, radians. Pixel (u, v) = (column,
row); the centre of the top-left pixel is (0, 0).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole camera intrinsics for an image of ``width`` x ``height`` pixels.

    Attributes:
        width: image width in pixels.
        height: image height in pixels.
        fx: focal length along x, pixels.
        fy: focal length along y, pixels.
        cx: principal point x, pixels (centre of the top-left pixel is 0).
        cy: principal point y, pixels.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        values = (self.fx, self.fy, self.cx, self.cy)
        if not all(np.isfinite(v) for v in values) or self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive and finite, got {values}")

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    def matrix(self) -> np.ndarray:
        """The 3x3 calibration matrix K, float64."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    def scaled(self, width: int, height: int) -> Intrinsics:
        """Intrinsics of the same camera after resizing the image to ``width`` x ``height``.

        A resize maps pixel edges onto pixel edges, so with pixel centres at integer
        coordinates: u' = (u + 0.5) * sx - 0.5, sx = width / self.width.
        """
        sx = width / self.width
        sy = height / self.height
        return Intrinsics(
            width=int(width),
            height=int(height),
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
        )

    def cropped(self, left: int, top: int, right: int = 0, bottom: int = 0) -> Intrinsics:
        """Intrinsics after removing ``left``/``top``/``right``/``bottom`` pixels at the borders."""
        if min(left, top, right, bottom) < 0:
            raise ValueError("crop margins must be non-negative")
        width = self.width - left - right
        height = self.height - top - bottom
        if width <= 0 or height <= 0:
            raise ValueError(f"crop leaves no image: {self.width}x{self.height} minus margins")
        return replace(self, width=width, height=height, cx=self.cx - left, cy=self.cy - top)


@dataclass(frozen=True, eq=False)
class Frame:
    """One RGB-D frame as every reader delivers it.

    Attributes:
        index: position of the frame in its sequence (0-based, after any start/stride).
        rgb: (H, W, 3) uint8 colour image.
        depth: (H, W) float32 depth along the optical axis in metres; 0 = invalid.
        intrinsics: camera intrinsics of ``rgb`` and ``depth`` (registered images).
        pose_gt: (4, 4) float64 ground-truth camera-to-world pose (OpenCV axes), or
            None when the sequence has no ground truth for this frame.
        timestamp: seconds; the frame index when the dataset has no time stamps.
        colour_delay: seconds from the depth image to the colour image (colour time
            minus depth time); 0 where both are taken together or the reader cannot
            tell (TUM's reader reads it).
    """

    index: int
    rgb: np.ndarray
    depth: np.ndarray
    intrinsics: Intrinsics
    pose_gt: np.ndarray | None = None
    timestamp: float = 0.0
    colour_delay: float = 0.0

    def __post_init__(self) -> None:
        h, w = self.intrinsics.height, self.intrinsics.width
        if self.rgb.shape != (h, w, 3) or self.rgb.dtype != np.uint8:
            raise ValueError(
                f"frame {self.index}: rgb must be ({h}, {w}, 3) uint8, "
                f"got {self.rgb.shape} {self.rgb.dtype}"
            )
        if self.depth.shape != (h, w) or self.depth.dtype != np.float32:
            raise ValueError(
                f"frame {self.index}: depth must be ({h}, {w}) float32, "
                f"got {self.depth.shape} {self.depth.dtype}"
            )
        if self.pose_gt is not None and self.pose_gt.shape != (4, 4):
            raise ValueError(f"frame {self.index}: pose_gt must be 4x4, got {self.pose_gt.shape}")

    @property
    def valid_depth(self) -> np.ndarray:
        """(H, W) bool mask of pixels with a usable depth (finite and > 0)."""
        return np.isfinite(self.depth) & (self.depth > 0)


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """A triangle mesh with vertex colours (world frame).

    Attributes:
        vertices: (V, 3) float64, metres.
        faces: (F, 3) int64 vertex indices.
        colours: (V, 3) uint8 RGB.
    """

    vertices: np.ndarray
    faces: np.ndarray
    colours: np.ndarray


@dataclass(frozen=True, eq=False)
class RayBatch:
    """Rays to render, with what the sensor measured along them.

    Directions are the camera-frame directions with unit z rotated into the world, so
    a sample at parameter z along a ray lies at depth z along the camera's optical axis.

    Attributes:
        origins: (N, 3) ray origins (camera centres), world frame, metres.
        directions: (N, 3) world-frame directions, unit z in the camera frame.
        depth: (N,) measured depth along the optical axis, metres; 0 = no depth.
        rgb: (N, 3) measured colour in [0, 1].
    """

    origins: torch.Tensor
    directions: torch.Tensor
    depth: torch.Tensor
    rgb: torch.Tensor

    def __len__(self) -> int:
        return self.origins.shape[0]


@dataclass(frozen=True, eq=False)
class FieldOutput:
    """What the scene field returns for N points.

    Attributes:
        sdf: (N,) truncated signed distance in units of the truncation T, in [-1, 1].
        rgb: (N, 3) colour in [0, 1], or None when colour was not asked for.
    """

    sdf: torch.Tensor
    rgb: torch.Tensor | None


@dataclass(frozen=True, eq=False)
class RenderOutput:
    """Volume rendering of a RayBatch with S samples per ray.

    Attributes:
        depth: (N,) rendered depth, metres.
        rgb: (N, 3) rendered colour in [0, 1], or None when colour is not rendered.
        z_vals: (N, S) sample positions along each ray (depth along the optical axis).
        sdf: (N, S) predicted TSDF at the samples, units of T.
        weights: (N, S) rendering weights w_i = alpha_i prod_{j<i} (1 - alpha_j).
    """

    depth: torch.Tensor
    rgb: torch.Tensor | None
    z_vals: torch.Tensor
    sdf: torch.Tensor
    weights: torch.Tensor


@dataclass(frozen=True, eq=False)
class LossTerms:
    """The five loss terms (unweighted) and their weighted sum.

    Attributes:
        free_space, trunc_middle, trunc_tail, depth, colour: scalar tensors, unweighted.
        total: scalar tensor, the weighted sum that is optimised.
    """

    free_space: torch.Tensor
    trunc_middle: torch.Tensor
    trunc_tail: torch.Tensor
    depth: torch.Tensor
    colour: torch.Tensor
    total: torch.Tensor
