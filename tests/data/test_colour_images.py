"""read_rgb on colour files that are not 8-bit RGB: grey, 16-bit grey, RGBA, float."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from eslam.data.base import read_rgb
from eslam.errors import InputError


def test_16_bit_grey_png_is_scaled_to_8_bits_not_read_as_white(tmp_path: Path) -> None:
    """Issue 15: a 16-bit grey colour PNG was read as all white (Pillow clips at 255)."""
    grey = np.array([[0, 257, 32768], [65535, 1000, 50000]], dtype=np.uint16)
    path = tmp_path / "grey16.png"
    Image.fromarray(grey).save(path)
    assert Image.open(path).mode.startswith("I")  # the case Pillow's convert() clips
    rgb = read_rgb(path)
    assert rgb.shape == (2, 3, 3) and rgb.dtype == np.uint8
    expected = np.round(grey.astype(np.float64) * 255 / 65535).astype(np.uint8)
    for channel in range(3):
        np.testing.assert_array_equal(rgb[:, :, channel], expected)


def test_8_bit_grey_is_replicated_and_rgba_drops_alpha(tmp_path: Path) -> None:
    grey = np.arange(12, dtype=np.uint8).reshape(3, 4) * 20
    Image.fromarray(grey).save(tmp_path / "grey.png")
    rgb = read_rgb(tmp_path / "grey.png")
    np.testing.assert_array_equal(rgb, np.repeat(grey[:, :, None], 3, axis=2))
    rgba = np.zeros((3, 4, 4), dtype=np.uint8)
    rgba[..., 0], rgba[..., 3] = 200, 10
    Image.fromarray(rgba).save(tmp_path / "rgba.png")
    np.testing.assert_array_equal(read_rgb(tmp_path / "rgba.png")[..., 0], 200)


def test_16_bit_rgb_png_keeps_its_colours(tmp_path: Path) -> None:
    """A 48-bit RGB PNG (written by hand: Pillow cannot) reads as its top 8 bits."""
    import struct
    import zlib

    height, width = 2, 2
    pixels = np.array([[[65535, 0, 0], [0, 65535, 0]], [[0, 0, 65535], [32896, 32896, 32896]]])
    rows = b"".join(b"\x00" + pixels[y].astype(">u2").tobytes() for y in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
    png += chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")
    path = tmp_path / "rgb48.png"
    path.write_bytes(png)
    rgb = read_rgb(path)
    np.testing.assert_array_equal(rgb[0, 0], [255, 0, 0])
    np.testing.assert_array_equal(rgb[1, 0], [0, 0, 255])
    np.testing.assert_array_equal(rgb[1, 1], [128, 128, 128])


def test_float_colour_image_is_refused_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / "float.tiff"
    Image.fromarray(np.full((3, 4), 0.5, dtype=np.float32)).save(path)
    with pytest.raises(InputError, match="pixel mode F") as caught:
        read_rgb(path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)
