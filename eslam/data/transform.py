"""Resize and crop of registered colour + depth images, with the intrinsics to match.

Readers that change the image geometry (ScanNet's border crop, TUM's resize and crop)
apply one :class:`ImageTransform` to colour, depth and intrinsics alike, so the three
always agree. Colour is resampled bilinearly (antialiased when shrinking); depth with
nearest neighbour, which never blends a foreground and a background depth into a value
that lies on neither surface, and keeps 0 (invalid) pixels invalid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import Image

from eslam.errors import ConfigError
from eslam.types import Intrinsics


@dataclass(frozen=True)
class ImageTransform:
    """Resize to ``size`` (when given), then remove ``crop`` pixels on every side.

    Attributes:
        size: (width, height) after resizing, or None to keep the input size.
        crop: pixels removed on each of the four borders after the resize.
    """

    size: tuple[int, int] | None = None
    crop: int = 0

    def __post_init__(self) -> None:
        if self.crop < 0:
            raise ValueError(f"crop must be >= 0, got {self.crop}")
        if self.size is not None and min(self.size) <= 0:
            raise ValueError(f"resize target must be positive, got {self.size}")

    @property
    def is_identity(self) -> bool:
        """True when the transform changes nothing."""
        return self.size is None and self.crop == 0

    def intrinsics(self, intrinsics: Intrinsics) -> Intrinsics:
        """The intrinsics of images this transform produced from images of ``intrinsics``.

        Raises:
            ConfigError: the crop would leave no image (``data.crop`` names the fix); the
                readers call this when they open a sequence, before any frame is used.
        """
        if self.size is not None and self.size != intrinsics.size:
            intrinsics = intrinsics.scaled(*self.size)
        if 2 * self.crop >= min(intrinsics.size):
            width, height = intrinsics.size
            raise ConfigError(
                f"data.crop={self.crop} removes {self.crop} pixels on every border of a "
                f"{width}x{height} image (after any resize), leaving nothing: "
                f"set data.crop below {(min(width, height) + 1) // 2}"
            )
        if self.crop:
            intrinsics = intrinsics.cropped(self.crop, self.crop, self.crop, self.crop)
        return intrinsics

    def colour(self, rgb: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 -> (H', W', 3) uint8."""
        if self.size is not None and self.size != (rgb.shape[1], rgb.shape[0]):
            resized = Image.fromarray(rgb).resize(self.size, Image.Resampling.BILINEAR)
            rgb = np.asarray(resized, dtype=np.uint8)
        return self._crop(rgb)

    def depth(self, depth: np.ndarray) -> np.ndarray:
        """(H, W) float32 metres -> (H', W') float32 metres; nearest-neighbour resampling."""
        if self.size is not None and self.size != (depth.shape[1], depth.shape[0]):
            image = Image.fromarray(depth.astype(np.float32), mode="F")
            depth = np.asarray(image.resize(self.size, Image.Resampling.NEAREST), np.float32)
        return self._crop(depth)

    def _crop(self, image: np.ndarray) -> np.ndarray:
        if not self.crop:
            return np.ascontiguousarray(image)
        c = self.crop
        return np.ascontiguousarray(image[c:-c, c:-c])


def transform_from_options(
    resize: tuple[int, int] | list[int] | None,
    crop: int | None,
    default_size: tuple[int, int] | None = None,
    default_crop: int = 0,
) -> ImageTransform:
    """The transform a reader applies: ``data.resize`` / ``data.crop``, or its defaults.

    ``None`` means "the layout's default"; an explicit 0 crop is kept (no crop).
    """
    size = tuple(resize) if resize is not None else default_size
    return ImageTransform(size, default_crop if crop is None else crop)
