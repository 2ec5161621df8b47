"""Depth as images: 16-bit millimetres (PNG files, the viewer's stream) and colours (videos).

The colours are Turbo (Mikhailov, "Turbo, an improved rainbow colormap for
visualization", Google AI blog, 2019), without matplotlib, through its degree-5
polynomial approximation (Ruofei Du's, published with it): each channel
c(x) = sum_k a_k x^k, k = 0..5, x in [0, 1], clipped to [0, 1].
"""

from __future__ import annotations

import numpy as np

TURBO_POLYNOMIAL = np.array(
    [
        [0.13572138, 4.61539260, -42.66032258, 132.13108234, -152.94239396, 59.28637943],
        [0.09140261, 2.19418839, 4.84296658, -14.18503333, 4.27729857, 2.82956604],
        [0.10667330, 12.64194608, -60.58204836, 110.36276771, -89.90310912, 27.34824973],
    ]
)
"""Coefficients a_0..a_5 of red, green and blue (rows)."""


def turbo(x: np.ndarray) -> np.ndarray:
    """(..., 3) uint8 Turbo colours of ``x`` (...), values clipped to [0, 1] first."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    powers = x[..., None] ** np.arange(6)
    rgb = np.clip(powers @ TURBO_POLYNOMIAL.T, 0.0, 1.0)
    return np.round(255.0 * rgb).astype(np.uint8)


def depth_colours(depth: np.ndarray, near: float, far: float) -> np.ndarray:
    """(H, W, 3) uint8: ``depth`` (H, W) metres mapped by :func:`turbo` from ``near``
    (blue) to ``far`` (red); pixels with depth 0 (nothing there) are black."""
    if not far > near:
        raise ValueError(f"the depth range needs far > near, got {near}..{far}")
    colours = turbo((depth - near) / (far - near))
    colours[~(depth > 0)] = 0
    return colours


def depth_millimetres(depth: np.ndarray) -> np.ndarray:
    """(H, W) uint16 millimetres of ``depth`` (H, W) metres: round(1000 d), 0 where
    nothing was measured or hit (depth 0 or not finite); depths past 65.535 m are
    clipped to it (the format's largest)."""
    millimetres = np.round(np.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0) * 1000.0)
    return np.clip(millimetres, 0, np.iinfo(np.uint16).max).astype(np.uint16)
