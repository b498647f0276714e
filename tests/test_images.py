"""Image I/O: round trips of every linear format, PNG tone mapping, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.errors import ImageError
from lightprobe.images import linear_to_srgb, read_image, srgb_to_linear, write_image, write_png


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


@pytest.mark.parametrize("damage", ["truncated", "garbage in its chunks", "garbage at the start"])
def test_a_corrupt_png_is_one_line_and_nothing_else_is_printed(tmp_path, capfd, damage):
    """libpng printed its own 'libpng error: ...' line on the process's stderr before lightprobe's error, and
    OpenImageIO's message ran over three lines; read as a map or as a texture, the error is one line, alone."""
    from lightprobe.textures import ImageTexture

    codes = np.random.default_rng(3).integers(0, 256, (16, 16, 3))
    good = _write_8bit(tmp_path / "good.png", codes).read_bytes()
    bad = tmp_path / "bad.png"
    bad.write_bytes({"truncated": good[: len(good) // 2], "garbage in its chunks": good[:60] + b"\0" * 60 + good[120:],
                     "garbage at the start": b"\xab" * 16 + good[16:]}[damage])  # fmt: skip
    capfd.readouterr()
    for read in (read_image, ImageTexture.read):
        with pytest.raises(ImageError) as info:
            read(bad)
        message = str(info.value)
        assert message.startswith(f"{bad}: cannot read image") and "\n" not in message, message
    assert capfd.readouterr() == ("", "")


def test_a_librarys_output_is_held_and_written_out_only_after_a_read_that_succeeded(capfd):
    """What a library prints during a read that fails is in the error; after one that succeeds (a libpng warning)
    it is written out as before."""
    import os

    from lightprobe.errors import library_output_held

    with library_output_held() as succeeded:
        os.write(2, b"libpng warning: kept\n")
        succeeded.append(True)
    with pytest.raises(ImageError), library_output_held():
        os.write(2, b"libpng error: dropped\n")
        raise ImageError("bad.png: cannot read image")
    assert capfd.readouterr() == ("", "libpng warning: kept\n")


def _write_8bit(path, codes):
    import OpenImageIO as oiio

    codes = np.asarray(codes, dtype=np.uint8)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(codes.shape[1], codes.shape[0], codes.shape[2], oiio.UINT8))
    out.write_image(np.ascontiguousarray(codes))
    out.close()
    return path


@pytest.mark.parametrize("ext", [".png", ".jpg", ".tif"])
def test_display_encoded_images_are_decoded_to_linear_with_the_srgb_curve(tmp_path, ext):
    import warnings

    from lightprobe.errors import LightprobeWarning
    from lightprobe.images import read_radiance

    codes = np.tile(np.array([0, 10, 64, 128, 200, 255], np.uint8)[None, :, None], (2, 1, 3))
    path = _write_8bit(tmp_path / f"ldr{ext}", codes)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        linear = read_radiance(path)
        read_radiance(path)  # a second read says nothing new
    assert [str(w.message).startswith(f"{path}: a display-encoded") for w in caught] == [True]
    assert caught[0].category is LightprobeWarning
    c = read_image(path)[0, :, 0].astype(np.float64)  # stored code values / 255 (JPEG: after its lossy coding)
    # IEC 61966-2-1, written out by hand: linear below 0.04045, a 2.4 power with an offset above
    expected = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(linear[0, :, 0], expected, rtol=1e-6, atol=1e-7)
    if ext == ".png":  # the exact codes: 128 -> 0.21586 (a 2.2 power would give 0.21953)
        assert linear[0, 3, 0] == pytest.approx(0.2158605, abs=2e-7)


@pytest.mark.parametrize("ext", [".exr", ".hdr", ".pfm"])
def test_linear_formats_are_read_as_stored(tmp_path, ext):
    import warnings

    from lightprobe.images import read_radiance

    img = np.array([[[0.25, 0.5, 4.0], [1e3, 0.0, 0.125]]], np.float32)
    path = write_image(tmp_path / f"lin{ext}", img)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(read_radiance(path), read_image(path))


def test_png_output_is_the_srgb_encoding_of_the_linear_values(tmp_path):
    linear = np.array([[[0.0, 0.002, 0.0031308], [0.18, 0.5, 1.0], [2.0, -1.0, np.nan]]], np.float32)
    codes = read_image(write_png(tmp_path / "o.png", linear)) * 255.0
    x = np.clip(np.nan_to_num(linear.astype(np.float64)), 0, 1)
    expected = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055) * 255.0
    np.testing.assert_allclose(codes, np.round(expected), atol=1e-3)


def test_a_failed_write_leaves_the_old_file_and_no_partial_file(tmp_path, monkeypatch):
    import OpenImageIO as oiio

    path = write_image(tmp_path / "keep.exr", np.ones((2, 2, 3), np.float32))
    before = path.read_bytes()

    class Broken:
        @staticmethod
        def create(name):
            class Out:
                def open(self, *args):
                    return True

                def write_image(self, pixels):
                    return False

                def geterror(self):
                    return "No space left on device"

                def close(self):
                    pass

            return Out()

    monkeypatch.setattr(oiio, "ImageOutput", Broken)
    with pytest.raises(ImageError, match=r"keep.exr: cannot write \(No space left on device\)"):
        write_image(path, np.zeros((2, 2, 3), np.float32))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.exr"]
