"""Image I/O: round trips of every linear format, PNG tone mapping, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.errors import ImageError
from lightprobe.io.images import linear_to_srgb, read_image, srgb_to_linear, write_image, write_png


@pytest.mark.parametrize("ext", [".exr", ".pfm", ".hdr"])
def test_round_trip(tmp_path, ext):
    img = (np.random.default_rng(0).random((5, 7, 3)) * 100).astype(np.float32)
    img[0, 0] = (1e4, 0.5, 0.0)  # orientation marker: top-left
    back = read_image(write_image(tmp_path / f"x{ext}", img))
    assert back.shape == img.shape
    if ext == ".hdr":  # RGBE: 8-bit mantissas under a shared exponent, so error relative to the pixel's max
        tolerance = img.max(axis=2, keepdims=True) / 128.0
        assert np.all(np.abs(back - img) <= tolerance)
    else:
        np.testing.assert_array_equal(back, img)


def test_exr_extra_channels(tmp_path):
    img = np.random.default_rng(1).random((3, 4, 6)).astype(np.float32)
    names = ["R", "G", "B", "variance.R", "variance.G", "variance.B"]
    back = read_image(write_image(tmp_path / "v.exr", img, channel_names=names))
    np.testing.assert_array_equal(back, img)


def test_png_is_srgb_encoded_and_never_nan(tmp_path):
    img = np.array([[[0.0, 0.5, 1.0], [np.nan, np.inf, 4.0]]], np.float32)
    back = read_image(write_png(tmp_path / "t.png", img))
    assert back.shape == (1, 2, 3)
    expected = np.round(linear_to_srgb(np.array([0.0, 0.5, 1.0, 0.0, 0.0, 1.0])) * 255) / 255
    np.testing.assert_allclose(back.reshape(-1), expected, atol=1e-6)


def test_srgb_curve_round_trip():
    x = np.linspace(0, 1, 101)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)
    assert linear_to_srgb(np.array(0.5)) == pytest.approx(0.7353569830524495)


def test_errors(tmp_path):
    with pytest.raises(ImageError, match="no such file"):
        read_image(tmp_path / "missing.exr")
    (tmp_path / "bad.exr").write_bytes(b"nonsense")
    with pytest.raises(ImageError, match=r"bad\.exr"):
        read_image(tmp_path / "bad.exr")
    (tmp_path / "short.pfm").write_bytes(b"PF\n4 4\n-1\n" + b"\0" * 12)
    with pytest.raises(ImageError, match="truncated"):
        read_image(tmp_path / "short.pfm")
    with pytest.raises(ImageError, match="unsupported"):
        write_image(tmp_path / "x.tiff", np.zeros((2, 2, 3)))
