"""ImageTransform: resize + crop of colour and depth with matching intrinsics."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eslam.data.transform import ImageTransform
from eslam.errors import ConfigError
from eslam.geometry.camera import project_points
from eslam.types import Intrinsics

CAMERA = Intrinsics(width=640, height=480, fx=517.3, fy=516.5, cx=318.6, cy=255.3)


def test_tum_resize_and_crop_intrinsics() -> None:
    # the release's TUM preprocessing: 640x480 -> 512x384, then 8 px off every border
    k = ImageTransform((512, 384), 8).intrinsics(CAMERA)
    assert k.size == (496, 368)
    assert k.fx == pytest.approx(517.3 * 0.8)
    assert k.fy == pytest.approx(516.5 * 0.8)
    assert k.cx == pytest.approx((318.6 + 0.5) * 0.8 - 0.5 - 8)
    assert k.cy == pytest.approx((255.3 + 0.5) * 0.8 - 0.5 - 8)


def test_images_match_their_intrinsics() -> None:
    """A point's pixel before and after the transform lands on the same image content."""
    transform = ImageTransform((320, 240), 10)
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 255, (480, 640, 3), dtype=np.uint8)
    depth = np.zeros((480, 640), np.float32)
    depth[200:280, 300:380] = 2.5  # an 80x80 block at 2.5 m
    out_rgb, out_depth = transform.colour(rgb), transform.depth(depth)
    k = transform.intrinsics(CAMERA)
    assert out_rgb.shape == (220, 300, 3) and out_rgb.dtype == np.uint8
    assert out_depth.shape == (220, 300) and out_depth.dtype == np.float32
    # nearest neighbour keeps depth values exact: nothing blended between 0 and 2.5
    assert set(np.unique(out_depth).tolist()) == {0.0, 2.5}
    # the block's centre (339.5, 239.5), back-projected and projected with the new
    # intrinsics, lands on the block's centre in the new image
    x = (339.5 - CAMERA.cx) / CAMERA.fx * 2.5
    y = (239.5 - CAMERA.cy) / CAMERA.fy * 2.5
    uv, z = project_points(
        torch.tensor([[x, y, 2.5]], dtype=torch.float64), k, torch.eye(4).double()
    )
    u, v = uv[0].tolist()
    assert float(z[0]) == pytest.approx(2.5)
    assert out_depth[round(v), round(u)] == 2.5
    rows, cols = np.nonzero(out_depth)
    assert abs(cols.mean() - u) < 0.6 and abs(rows.mean() - v) < 0.6


def test_identity_changes_nothing() -> None:
    transform = ImageTransform()
    depth = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert transform.is_identity
    assert transform.intrinsics(CAMERA) == CAMERA
    np.testing.assert_array_equal(transform.depth(depth), depth)


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="crop"):
        ImageTransform(crop=-1)
    with pytest.raises(ConfigError, match=r"data.crop=240 .* 640x480 .* below 240"):
        ImageTransform(crop=240).intrinsics(CAMERA)
    assert ImageTransform(crop=239).intrinsics(CAMERA).size == (162, 2)
    with pytest.raises(ConfigError, match=r"data.crop=100 .* 320x160 .* below 80"):
        ImageTransform((320, 160), crop=100).intrinsics(CAMERA)


def test_crop_larger_than_the_image_is_one_line_exit_2(tmp_path, capsys) -> None:
    """Issue 15: data.crop larger than the image was a traceback (exit 1)."""
    from eslam.cli import EXIT_USER_ERROR, main
    from eslam.synthetic import SynthConfig, write_synthetic_sequence
    from eslam.workflows.demo import DEMO_CONFIG

    data = tmp_path / "data"
    write_synthetic_sequence(data, SynthConfig(frames=2, width=32, height=24))
    out = tmp_path / "run"
    code = main(["run", str(DEMO_CONFIG), "--data", str(data), "--out", str(out), "data.crop=12"])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "data.crop=12" in err and "below 12" in err
    assert not out.exists()
