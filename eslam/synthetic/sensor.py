"""A depth sensor's flaws on exact synthetic depth: axial noise and missing pixels."""

from __future__ import annotations

import math

import numpy as np

from eslam.synthetic.config import SynthConfig
from eslam.synthetic.render import RenderedView

KINECT_AXIAL_NOISE = (0.0012, 0.0019, 0.4)
"""(a, b, z0) of sigma(z) = a + b (z - z0)^2 m: Nguyen, Izadi, Lovell, 3DIMPVT 2012."""
MISSING_FRACTION = 0.02
"""Fraction of pixels dropped at random when ``missing_depth`` is on."""
GRAZING_COSINE = math.cos(math.radians(78.0))
"""Depth is missing where |cos(ray, normal)| is below this (grazing surfaces)."""
EDGE_JUMP = 0.05
"""Depth is missing beside a jump larger than this fraction of the depth (discontinuities)."""


def sensor_depth(view: RenderedView, rng: np.random.Generator, config: SynthConfig) -> np.ndarray:
    """Depth as a Kinect-like sensor would give it (see ``depth_noise``, ``missing_depth``).

    Returns:
        (H, W) float32 metres, 0 = missing.
    """
    exact = view.depth.astype(np.float64)
    depth = exact.copy()
    if config.depth_noise:
        a, b, z0 = KINECT_AXIAL_NOISE
        depth += rng.normal(size=depth.shape) * (a + b * (exact - z0) ** 2)
    if config.missing_depth:
        missing = (rng.random(depth.shape) < MISSING_FRACTION) | (
            view.cos_incidence < GRAZING_COSINE
        )
        padded = np.pad(exact, 1, mode="edge")
        for neighbour in (padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]):
            missing |= np.abs(neighbour - exact) > EDGE_JUMP * np.minimum(neighbour, exact)
        depth[missing] = 0.0
    depth[exact <= 0] = 0.0
    return np.maximum(depth, 0.0).astype(np.float32)
