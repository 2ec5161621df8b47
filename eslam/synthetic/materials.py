"""Appearance of synthetic scenes: procedural materials and view-independent shading.

A :class:`Material` gives the albedo at any world point: a smooth two-colour gradient
with a sharp pattern (checker, stripes or rings) over it. The rendered colour is albedo
times :func:`shading`, which depends only on the surface normal, so it is the same from
every viewpoint (used both by the ray caster and for the ground-truth mesh colours).
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass

import numpy as np

LIGHT_DIRECTION = np.array([0.36, 0.48, 0.8]) / np.linalg.norm([0.36, 0.48, 0.8])
"""Unit direction towards the (infinitely far) light, world frame."""
AMBIENT = 0.6
"""Shading = AMBIENT + (1 - AMBIENT) * (1 + n.l) / 2: never black, view-independent."""
PATTERNS = ("checker", "stripes", "rings")


@dataclass(frozen=True, eq=False)
class Material:
    """A procedural texture: a smooth two-colour gradient with a sharp pattern over it.

    albedo(p) = lerp(low, high, g(p)) * ripple(p), then lerp towards ``accent`` by
    ``strength`` where the pattern is on; g = (1 + sin(wave.p + phase)) / 2 and
    ripple = 0.85 + 0.15 sin(ripple.p). The gradients give the colour loss slopes
    everywhere; the pattern gives edges.

    Attributes:
        low: (3,) RGB in [0, 1] at one end of the gradient.
        high: (3,) RGB at the other end.
        accent: (3,) RGB of the pattern.
        wave: (3,) wave vector of the gradient, rad/m.
        ripple: (3,) wave vector of a finer brightness ripple, rad/m.
        phase: gradient phase, rad.
        pattern: one of PATTERNS: "checker" (3D lattice of cubes), "stripes"
            (parallel slabs), "rings" (concentric spherical shells).
        scale: cell / stripe / ring width, m.
        vector: checker: lattice offset (m); stripes: unit normal of the slabs;
            rings: centre (m).
        strength: how far towards ``accent`` the pattern pulls, in [0, 1].
    """

    low: np.ndarray
    high: np.ndarray
    accent: np.ndarray
    wave: np.ndarray
    ripple: np.ndarray
    phase: float
    pattern: str
    scale: float
    vector: np.ndarray
    strength: float

    def albedo(self, points: np.ndarray) -> np.ndarray:
        """(M, 3) RGB in [0, 1] at world ``points`` (M, 3)."""
        g = 0.5 + 0.5 * np.sin(points @ self.wave + self.phase)
        base = self.low + g[:, None] * (self.high - self.low)
        base *= (0.85 + 0.15 * np.sin(points @ self.ripple))[:, None]
        if self.pattern == "checker":
            cells = np.floor((points + self.vector) / self.scale).sum(axis=1)
        elif self.pattern == "stripes":
            cells = np.floor(points @ self.vector / self.scale)
        else:
            cells = np.floor(np.linalg.norm(points - self.vector, axis=1) / self.scale)
        on = (np.mod(cells, 2.0) * self.strength)[:, None]
        return base * (1.0 - on) + self.accent * on


def _hsv(hue: float, saturation: float, value: float) -> np.ndarray:
    return np.array(colorsys.hsv_to_rgb(hue % 1.0, min(saturation, 1.0), min(value, 1.0)))


def _unit(rng: np.random.Generator) -> np.ndarray:
    """A random unit vector with every component at least ~0.2: no face sees it edge-on."""
    vector = rng.uniform(0.35, 1.0, 3) * rng.choice([-1.0, 1.0], 3)
    return vector / np.linalg.norm(vector)


def random_material(
    rng: np.random.Generator, hue: float, value: float, saturation: float
) -> Material:
    """A material whose colours stay near ``hue`` and ``value`` (distinct mean colours)."""
    pattern = PATTERNS[int(rng.integers(len(PATTERNS)))]
    scale = rng.uniform(0.08, 0.3)
    vector = {
        "checker": rng.uniform(0.0, scale, 3),
        "stripes": _unit(rng),
        "rings": rng.uniform(-3.0, 3.0, 3),
    }[pattern]
    return Material(
        low=_hsv(hue, saturation, 0.7 * value),
        high=_hsv(hue + 0.05, 0.8 * saturation, 1.25 * value),
        accent=_hsv(hue + rng.choice([-0.1, 0.1]), saturation, rng.choice([0.25, 0.98])),
        wave=_unit(rng) * 2 * math.pi / rng.uniform(1.0, 3.0),
        ripple=_unit(rng) * 2 * math.pi / rng.uniform(0.25, 0.6),
        phase=float(rng.uniform(0.0, 2 * math.pi)),
        pattern=pattern,
        scale=float(scale),
        vector=vector,
        strength=float(rng.uniform(0.5, 0.75)),
    )


def shading(normals: np.ndarray) -> np.ndarray:
    """(M,) view-independent shading factor in [AMBIENT, 1] for unit ``normals`` (M, 3)."""
    return AMBIENT + (1.0 - AMBIENT) * 0.5 * (1.0 + normals @ LIGHT_DIRECTION)
