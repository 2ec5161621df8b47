"""Colour-to-depth registration (eslam.data.registration) and the 7-Scenes reader's use of it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eslam.config import DataConfig
from eslam.data.registration import (
    ColourCamera,
    alignment_score,
    colour_pixel_of_depth_pixel,
    edge_view,
    register_colour,
)
from eslam.data.sevenscenes import (
    SEVENSCENES_COLOUR_CAMERA,
    SEVENSCENES_INTRINSICS,
    SevenScenesSequence,
)
from eslam.errors import InputError
from eslam.synthetic import SynthConfig, generate_sequence
from eslam.testing import write_sevenscenes_sequence
from eslam.types import Intrinsics

DEPTH_CAMERA = Intrinsics(160, 120, 146.0, 146.0, 80.0, 60.0)
COLOUR_CAMERA = ColourCamera(131.0, 131.0, 79.0, 61.0, (0.025, 0.0, 0.0))


def _pattern(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(..., 3) smooth colour of the world point (x, y) on a plane (0-255)."""
    return np.stack(
        [
            127.5 + 100 * np.sin(9.0 * x),
            127.5 + 100 * np.cos(7.0 * y),
            127.5 + 100 * np.sin(5.0 * (x + y)),
        ],
        axis=-1,
    )


def _plane_images(z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A textured fronto-parallel plane at depth ``z``: (colour as the colour camera
    sees it, depth in the depth camera, colour as the depth camera would see it)."""
    height, width = DEPTH_CAMERA.height, DEPTH_CAMERA.width
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    # Colour camera pixel -> its ray hits the plane z at x = (u - cx) z / f + centre_x.
    x_c = (u - COLOUR_CAMERA.cx) * z / COLOUR_CAMERA.fx + COLOUR_CAMERA.centre[0]
    y_c = (v - COLOUR_CAMERA.cy) * z / COLOUR_CAMERA.fy
    seen_by_colour = np.rint(_pattern(x_c, y_c)).astype(np.uint8)
    x_d = (u - DEPTH_CAMERA.cx) * z / DEPTH_CAMERA.fx
    y_d = (v - DEPTH_CAMERA.cy) * z / DEPTH_CAMERA.fy
    truth = _pattern(x_d, y_d)
    return seen_by_colour, np.full((height, width), z, np.float32), truth


def test_same_camera_is_the_identity() -> None:
    rgb = np.random.default_rng(0).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    depth = np.full((120, 160), 1.7, np.float32)
    same = ColourCamera.of_depth_camera(DEPTH_CAMERA)
    np.testing.assert_array_equal(register_colour(rgb, depth, DEPTH_CAMERA, same), rgb)


def test_parallax_shrinks_with_depth() -> None:
    # Same K, centre b along +x: u_c = u - f b / z (module equations).
    k = DEPTH_CAMERA
    shifted = ColourCamera(k.fx, k.fy, k.cx, k.cy, (0.05, 0.0, 0.0))
    for z in (0.5, 2.0):
        u_c, v_c = colour_pixel_of_depth_pixel(np.full((120, 160), z), k, shifted)
        np.testing.assert_allclose(u_c[7, :], np.arange(160) - k.fx * 0.05 / z, atol=1e-9)
        np.testing.assert_allclose(v_c[:, 3], np.arange(120), atol=1e-9)


def test_pixels_without_depth_use_the_median_depth() -> None:
    depth = np.full((120, 160), 1.0)
    depth[:, 100:] = 3.0
    depth[:10] = 0.0  # no depth: the median of the rest (1.0) applies
    u_c, _ = colour_pixel_of_depth_pixel(depth, DEPTH_CAMERA, COLOUR_CAMERA)
    with_median = np.where(depth > 0, depth, 1.0)
    u_expected, _ = colour_pixel_of_depth_pixel(with_median, DEPTH_CAMERA, COLOUR_CAMERA)
    np.testing.assert_allclose(u_c, u_expected)
    nothing, _ = colour_pixel_of_depth_pixel(np.zeros((120, 160)), DEPTH_CAMERA, COLOUR_CAMERA)
    assert np.isfinite(nothing).all()


def test_registered_plane_matches_the_depth_cameras_view() -> None:
    seen_by_colour, depth, truth = _plane_images(1.4)
    registered = register_colour(seen_by_colour, depth, DEPTH_CAMERA, COLOUR_CAMERA)
    # Away from the border (clamped where the colour camera saw less of the plane).
    inner = (slice(12, -12), slice(12, -12))
    error = np.abs(registered[inner].astype(np.float64) - truth[inner]).mean()
    raw_error = np.abs(seen_by_colour[inner].astype(np.float64) - truth[inner]).mean()
    assert error < 2.0, error
    assert raw_error > 10.0, raw_error


def test_edge_alignment_prefers_the_true_camera() -> None:
    # A box in front of a wall: depth edges at the box outline, colour edges too.
    height, width = DEPTH_CAMERA.height, DEPTH_CAMERA.width
    depth = np.full((height, width), 2.5)
    depth[40:80, 50:110] = 1.2
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    # Render the colour camera's image of the scene: its ray at (u, v) hits the box
    # where the box's projection into it lies.
    z = 1.2
    x = (u - COLOUR_CAMERA.cx) * z / COLOUR_CAMERA.fx + COLOUR_CAMERA.centre[0]
    y = (v - COLOUR_CAMERA.cy) * z / COLOUR_CAMERA.fy
    u_d = x * DEPTH_CAMERA.fx / z + DEPTH_CAMERA.cx
    v_d = y * DEPTH_CAMERA.fy / z + DEPTH_CAMERA.cy
    box = (u_d >= 50) & (u_d < 110) & (v_d >= 40) & (v_d < 80)
    rgb = np.where(box[..., None], 220, 40).astype(np.uint8).repeat(3, axis=-1)
    views = [edge_view(rgb, depth)]
    k = DEPTH_CAMERA
    raw = ColourCamera.of_depth_camera(k)
    assert alignment_score(views, k, COLOUR_CAMERA) > 1.5 * alignment_score(views, k, raw)


# --- the 7-Scenes reader ----------------------------------------------------------------


def test_reader_refuses_registration_for_other_image_sizes(tmp_path: Path) -> None:
    frames = list(generate_sequence(SynthConfig(frames=1, width=64, height=48, seed=5)))
    write_sevenscenes_sequence(tmp_path, frames)
    with pytest.raises(InputError, match=r"data\.register_colour=false") as caught:
        SevenScenesSequence(tmp_path)
    assert caught.value.path.name == "frame-000000.depth.png"
    assert "\n" not in str(caught.value)


@pytest.mark.realdata
def test_real_redkitchen_colour_is_registered(real_data: Path) -> None:
    root = real_data / "7scenes-redkitchen"
    raw = SevenScenesSequence(root, DataConfig(register_colour=False))
    registered = SevenScenesSequence(root)
    k = SEVENSCENES_INTRINSICS
    identity = ColourCamera.of_depth_camera(k)
    views = [edge_view(raw[i].rgb, raw[i].depth) for i in (0, 169, 350)]
    # Measured with benchmarks/colour_registration.py: 0.150 against 0.075 (8 frames).
    assert alignment_score(views, k, SEVENSCENES_COLOUR_CAMERA) > 1.6 * alignment_score(
        views, k, identity
    )
    frame = registered[169]
    expected = register_colour(raw[169].rgb, raw[169].depth, k, SEVENSCENES_COLOUR_CAMERA)
    np.testing.assert_array_equal(frame.rgb, expected)
    np.testing.assert_array_equal(frame.depth, raw[169].depth)
