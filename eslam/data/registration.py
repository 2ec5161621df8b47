"""Colour-to-depth registration of an RGB-D pair whose two cameras were never aligned.

Some recordings (Microsoft 7-Scenes) store the colour and depth images exactly as the
two cameras saw them: two pinholes a few centimetres apart with different focal
lengths. Treating the colour image as if the depth camera had taken it puts texture
tens of pixels away from the geometry near the image border. :func:`register_colour`
resamples the colour image into the depth camera's pixel grid:

    X = z K_d^-1 [u, v, 1]^T            (the depth pixel's 3-D point, depth-camera axes)
    [u_c, v_c, 1]^T ~ K_c (X - c)       (its projection into the colour camera)
    rgb_registered(u, v) = rgb(u_c, v_c)   (bilinear)

with ``c`` the colour camera's centre in depth-camera axes; the two cameras' axes are
taken as parallel (a Kinect v1's are to well under a degree). A pixel without depth
uses the image's median valid depth, the best single guess for its parallax.

Reference: the standard depth-to-colour mapping of RGB-D cameras (e.g. Herrera et al.,
"Joint depth and color camera calibration with distortion correction", TPAMI 2012,
eq. 1-3, without the distortion terms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from eslam.types import Intrinsics

FALLBACK_DEPTH_M = 2.0
"""Depth (m) assumed for every pixel of an image without any valid depth."""


@dataclass(frozen=True)
class ColourCamera:
    """The colour camera of an unregistered RGB-D pair, relative to the depth camera.

    Attributes:
        fx, fy, cx, cy: its pinhole intrinsics, pixels, for an image of the depth
            image's size.
        centre: (x, y, z) of its optical centre in depth-camera axes (OpenCV: x right,
            y down, z forward), metres.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    centre: tuple[float, float, float]

    @classmethod
    def of_depth_camera(cls, depth_camera: Intrinsics) -> ColourCamera:
        """The depth camera itself: colour read as if registered (no resampling needed)."""
        k = depth_camera
        return cls(k.fx, k.fy, k.cx, k.cy, (0.0, 0.0, 0.0))


def colour_pixel_of_depth_pixel(
    depth: np.ndarray, depth_camera: Intrinsics, colour_camera: ColourCamera
) -> tuple[np.ndarray, np.ndarray]:
    """Where each depth pixel's 3-D point falls in the colour image (module equations).

    Args:
        depth: (H, W) metres; 0 = no depth (the image's median valid depth is used).
        depth_camera: the depth image's intrinsics.
        colour_camera: the colour camera.

    Returns:
        (u_c, v_c): two (H, W) float64 arrays of colour-image pixel coordinates.
    """
    height, width = depth.shape
    valid = depth > 0
    fill = float(np.median(depth[valid])) if valid.any() else FALLBACK_DEPTH_M
    z = np.where(valid, depth, fill).astype(np.float64)
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    x = (u - depth_camera.cx) * z / depth_camera.fx
    y = (v - depth_camera.cy) * z / depth_camera.fy
    cx, cy, cz = colour_camera.centre
    zc = z - cz
    u_c = colour_camera.fx * (x - cx) / zc + colour_camera.cx
    v_c = colour_camera.fy * (y - cy) / zc + colour_camera.cy
    return u_c, v_c


def sample_bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) at real pixel coordinates (u, v), bilinear, edges clamped.

    Pixel centres are integers (the convention of :class:`Intrinsics`).
    """
    height, width = image.shape[:2]
    u = np.clip(u, 0.0, width - 1.0)
    v = np.clip(v, 0.0, height - 1.0)
    u0 = np.minimum(np.floor(u).astype(np.int64), width - 2)
    v0 = np.minimum(np.floor(v).astype(np.int64), height - 2)
    du = (u - u0)[..., None]
    dv = (v - v0)[..., None]
    pixels = image.astype(np.float32)
    top = pixels[v0, u0] * (1 - du) + pixels[v0, u0 + 1] * du
    bottom = pixels[v0 + 1, u0] * (1 - du) + pixels[v0 + 1, u0 + 1] * du
    return top * (1 - dv) + bottom * dv


def register_colour(
    rgb: np.ndarray, depth: np.ndarray, depth_camera: Intrinsics, colour_camera: ColourCamera
) -> np.ndarray:
    """The colour image resampled into the depth camera's pixels (module equations).

    Args:
        rgb: (H, W, 3) uint8 colour image as the colour camera took it.
        depth: (H, W) metres, 0 = no depth, in the depth camera.
        depth_camera: the depth image's intrinsics.
        colour_camera: the colour camera.

    Returns:
        (H, W, 3) uint8: the colour each depth pixel's point has.
    """
    u_c, v_c = colour_pixel_of_depth_pixel(depth, depth_camera, colour_camera)
    registered = sample_bilinear(rgb, u_c, v_c)
    return np.clip(np.rint(registered), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class EdgeView:
    """One raw frame prepared for :func:`alignment_score`.

    Attributes:
        gradient: (H, W, 1) colour gradient magnitude in [0, 1] (the colour camera).
        depth: (H, W) metres, 0 = none (the depth camera).
        edges: (H, W) weights on the depth image's discontinuities.
    """

    gradient: np.ndarray
    depth: np.ndarray
    edges: np.ndarray


def depth_edges(depth: np.ndarray, jump_m: float) -> np.ndarray:
    """(H, W) weights: 1 where the depth jumps by more than ``jump_m`` between
    neighbours (Sobel / 8), blurred by one pixel; 0 near invalid depth, whose borders
    are not geometry edges."""
    invalid = depth <= 0
    gradient = np.hypot(ndimage.sobel(depth, 0), ndimage.sobel(depth, 1)) / 8.0
    edges = (gradient > jump_m) & ~ndimage.binary_dilation(invalid, iterations=3)
    return ndimage.gaussian_filter(edges.astype(np.float64), 1.0)


def edge_view(rgb: np.ndarray, depth: np.ndarray, jump_m: float = 0.025) -> EdgeView:
    """An :class:`EdgeView` of a raw (colour, depth) pair: the grey image's Sobel
    magnitude (after a 1-pixel Gaussian) scaled to [0, 1], and :func:`depth_edges`."""
    grey = ndimage.gaussian_filter(rgb.astype(np.float64).mean(axis=-1), 1.0)
    magnitude = np.hypot(ndimage.sobel(grey, 0), ndimage.sobel(grey, 1))
    gradient = (magnitude / max(float(magnitude.max()), 1e-9))[..., None]
    return EdgeView(gradient, depth, depth_edges(depth, jump_m))


def alignment_score(views: list[EdgeView], depth_camera: Intrinsics, camera: ColourCamera) -> float:
    """How well ``camera`` registers colour to depth: the registered colour gradient
    averaged over the depth edges, mean over ``views``. Texture and geometry edges
    coincide where registration is right, so higher is better aligned."""
    scores = []
    for view in views:
        u_c, v_c = colour_pixel_of_depth_pixel(view.depth, depth_camera, camera)
        scores.append(edge_score(view, u_c, v_c))
    return float(np.mean(scores))


def edge_score(view: EdgeView, u: np.ndarray, v: np.ndarray) -> float:
    """The colour gradient of ``view`` read at colour pixels (u, v) (two (H, W) arrays,
    one per depth pixel), averaged over the depth edges: higher = better aligned."""
    moved = sample_bilinear(view.gradient, u, v)[..., 0]
    return float((moved * view.edges).sum() / max(float(view.edges.sum()), 1e-9))
