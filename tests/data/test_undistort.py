"""Plumb-bob distortion: the forward model by hand, its inverse, and image undistortion."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from eslam.data.undistort import (
    PlumbBob,
    Undistorter,
    distort_map,
    remap_bilinear,
    remap_nearest,
    undistort_map,
)
from eslam.types import Intrinsics

FR1 = Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3)
FR1_DISTORTION = PlumbBob(0.2624, -0.9531, -0.0054, 0.0026, 1.1633)


def test_forward_model_by_hand() -> None:
    # x = 0.3, y = -0.2: r2 = 0.13, radial = 1 + 0.2624*0.13 - 0.9531*0.0169 + 1.1633*0.002197
    #   = 1 + 0.034112 - 0.01610739 + 0.0025557701 = 1.0205603801
    # xd = 0.3 radial + 2 p1 x y + p2 (r2 + 2 x^2) = 0.30616811403 + 0.000648 + 0.000806
    # yd = -0.2 radial + p1 (r2 + 2 y^2) + 2 p2 x y = -0.20411207602 - 0.001134 - 0.000312
    r2 = 0.13
    radial = 1 + 0.2624 * r2 - 0.9531 * r2**2 + 1.1633 * r2**3
    assert radial == pytest.approx(1.0205603801, abs=1e-12)
    xd_expected = 0.3 * radial + 2 * -0.0054 * 0.3 * -0.2 + 0.0026 * (r2 + 2 * 0.09)
    yd_expected = -0.2 * radial + -0.0054 * (r2 + 2 * 0.04) + 2 * 0.0026 * 0.3 * -0.2
    xd, yd = FR1_DISTORTION.distort(np.array(0.3), np.array(-0.2))
    assert float(xd) == pytest.approx(xd_expected, abs=1e-15)
    assert float(yd) == pytest.approx(yd_expected, abs=1e-15)
    assert float(xd) == pytest.approx(0.30762211403, abs=1e-12)
    assert float(yd) == pytest.approx(-0.20555807602, abs=1e-12)


def test_inverse_recovers_points_over_the_image() -> None:
    # every distorted pixel of a 640x480 fr1 image, and a margin beyond it
    u, v = np.meshgrid(np.linspace(-20, 660, 69), np.linspace(-20, 500, 53))
    xd, yd = (u - FR1.cx) / FR1.fx, (v - FR1.cy) / FR1.fy
    x, y = FR1_DISTORTION.undistort(xd, yd)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(y))
    back_x, back_y = FR1_DISTORTION.distort(x, y)
    assert np.abs(back_x - xd).max() < 1e-10 and np.abs(back_y - yd).max() < 1e-10
    # the correction is real: up to several pixels at the border
    assert np.abs(x - xd).max() * FR1.fx > 5.0


def test_identity_distortion_changes_nothing() -> None:
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, size=(12, 16, 3), dtype=np.uint8)
    k = Intrinsics(16, 12, 20.0, 20.0, 7.5, 5.5)
    none = PlumbBob(0.0, 0.0, 0.0, 0.0)
    assert none.is_identity and not FR1_DISTORTION.is_identity
    np.testing.assert_array_equal(Undistorter(k, none).colour(image), image)


def _blob(centre: tuple[float, float], shape: tuple[int, int]) -> np.ndarray:
    v, u = np.mgrid[0 : shape[0], 0 : shape[1]]
    return np.exp(-((u - centre[0]) ** 2 + (v - centre[1]) ** 2) / (2 * 1.5**2))


def test_a_distorted_spot_lands_where_the_pinhole_sees_it() -> None:
    # A point at ideal pixel (560.0, 420.0): distorted by hand with the forward model.
    ideal = np.array([560.0, 420.0])
    x, y = (ideal[0] - FR1.cx) / FR1.fx, (ideal[1] - FR1.cy) / FR1.fy
    xd, yd = FR1_DISTORTION.distort(np.array(x), np.array(y))
    distorted = np.array([FR1.fx * xd + FR1.cx, FR1.fy * yd + FR1.cy])
    assert np.linalg.norm(distorted - ideal) > 3.0, "the point must move for a real test"
    image = np.repeat((255 * _blob(tuple(distorted), (480, 640)))[..., None], 3, axis=2)
    undistorted = Undistorter(FR1, FR1_DISTORTION).colour(image.round().astype(np.uint8))
    weight = undistorted[..., 0].astype(np.float64)
    v, u = np.mgrid[0:480, 0:640]
    centroid = np.array([(weight * u).sum(), (weight * v).sum()]) / weight.sum()
    np.testing.assert_allclose(centroid, ideal, atol=0.05)
    # depth: the one valid pixel maps to the output pixels whose distorted position rounds to it
    depth = np.zeros((480, 640), dtype=np.float32)
    source = np.floor(distorted + 0.5).astype(int)
    depth[source[1], source[0]] = 2.5
    out = Undistorter(FR1, FR1_DISTORTION).depth(depth)
    hits = np.argwhere(out > 0)
    assert len(hits) >= 1 and set(out[out > 0].tolist()) == {2.5}
    np.testing.assert_allclose(hits.mean(axis=0)[::-1], ideal, atol=1.0)


def test_maps_are_inverse_of_each_other() -> None:
    forward = undistort_map(FR1, FR1_DISTORTION)  # ideal pixel -> distorted position
    backward = distort_map(FR1, FR1_DISTORTION)  # distorted pixel -> ideal position
    u, v = np.meshgrid(np.arange(640.0), np.arange(480.0))
    # sample the backward map at the forward positions (where they are inside the image)
    inside = (forward[..., 0] >= 0) & (forward[..., 0] <= 639)
    inside &= (forward[..., 1] >= 0) & (forward[..., 1] <= 479)
    round_trip = remap_bilinear(backward, forward)
    error = np.hypot(round_trip[..., 0] - u, round_trip[..., 1] - v)[inside]
    assert error.max() < 0.01


def test_sampling_outside_gives_zero_and_depth_is_never_blended() -> None:
    image = np.full((4, 5), 7.0, dtype=np.float32)
    image[:, 3:] = 1.0
    coords = np.array([[[-0.5, 0.0], [2.5, 1.0], [9.0, 1.0], [np.nan, 0.0], [2.49, 1.0]]])
    np.testing.assert_allclose(remap_bilinear(image, coords), [[3.5, 4.0, 0.0, 0.0, 4.06]])
    np.testing.assert_array_equal(remap_nearest(image, coords), [[7.0, 1.0, 0.0, 0.0, 7.0]])


def test_against_opencv() -> None:
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(1)
    small = rng.integers(0, 256, size=(30, 40, 3), dtype=np.uint8)
    image = np.asarray(Image.fromarray(small).resize((640, 480), Image.Resampling.BILINEAR))
    coefficients = np.array([0.2624, -0.9531, -0.0054, 0.0026, 1.1633])
    undistorter = Undistorter(FR1, FR1_DISTORTION)
    reference = cv2.undistort(image, FR1.matrix(), coefficients)
    difference = np.abs(undistorter.colour(image).astype(int) - reference.astype(int))
    # OpenCV interpolates in fixed point (1/32 pixel): a grey level here and there
    assert difference.mean() < 0.1 and np.percentile(difference, 99.9) <= 2
    map_x, map_y = cv2.initUndistortRectifyMap(
        FR1.matrix(), coefficients, None, FR1.matrix(), (640, 480), cv2.CV_32FC1
    )
    depth = rng.uniform(0.5, 4.0, size=(480, 640)).astype(np.float32)
    reference_depth = cv2.remap(depth, map_x, map_y, cv2.INTER_NEAREST)
    ours = undistorter.depth(depth)
    assert (ours != reference_depth).mean() < 1e-4  # float32 map rounding at exact ties
    assert np.array_equal(ours == 0, reference_depth == 0)
