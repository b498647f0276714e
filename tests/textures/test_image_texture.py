"""Image textures: the lookup against a NumPy transcription of bilinear filtering and the three wrap modes, sRGB
decoding of 8-bit texels, storage and memory, and refused inputs."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.errors import ImageError, ParameterError
from lightprobe.textures import ImageTexture, pack_textures
from lightprobe.textures.image_texture import SRGB_TABLE, lookup_batch


def _wrap(i, n, mode):
    if mode == "repeat":
        return np.mod(i, n)
    if mode == "mirrored_repeat":
        j = np.mod(i, 2 * n)
        return np.where(j < n, j, 2 * n - 1 - j)
    return np.clip(i, 0, n - 1)


def _bilinear(pixels, uv, wrap):
    """glTF bilinear filtering written out: texel centres at (i + 1/2) / W, four neighbours, per-axis wrap."""
    h, w = pixels.shape[:2]
    x, y = uv[:, 0] * w - 0.5, uv[:, 1] * h - 0.5
    i0, j0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    ax, ay = (x - i0)[:, None], (y - j0)[:, None]
    i1, j1 = _wrap(i0 + 1, w, wrap[0]), _wrap(j0 + 1, h, wrap[1])
    i0, j0 = _wrap(i0, w, wrap[0]), _wrap(j0, h, wrap[1])
    p = pixels.astype(np.float64)
    return (1 - ax) * (1 - ay) * p[j0, i0] + ax * (1 - ay) * p[j0, i1] + (1 - ax) * ay * p[j1, i0] + ax * ay * p[j1, i1]


@pytest.mark.parametrize("wrap", [("repeat", "repeat"), ("mirrored_repeat", "clamp"), ("clamp", "mirrored_repeat")])
def test_bilinear_lookup_and_wrap_modes_match_the_formula(wrap):
    rng = np.random.default_rng(3)
    pixels = rng.random((5, 7, 4)).astype(np.float32)  # odd sizes on purpose
    texture = ImageTexture(pixels, wrap=wrap)
    uv = rng.uniform(-2.5, 3.5, size=(4000, 2))  # well outside [0, 1]: every wrap mode's folds
    got = lookup_batch(pack_textures([texture]), 0, uv, srgb=False)
    # the kernel first folds the coordinate into one period (so that huge ones cannot overflow); equal up to that
    # rounding
    np.testing.assert_allclose(got, _bilinear(pixels, uv, wrap), rtol=0, atol=2e-6)


def test_texel_centres_return_the_texel_and_nearest_filtering_picks_the_texel_under_the_point():
    rng = np.random.default_rng(4)
    pixels = rng.integers(0, 256, size=(3, 4, 4), dtype=np.uint8)
    j, i = np.mgrid[0:3, 0:4]
    centres = np.column_stack([(i.ravel() + 0.5) / 4, (j.ravel() + 0.5) / 3])
    expected = pixels.reshape(-1, 4) / 255.0
    linear = pack_textures([ImageTexture(pixels)])
    np.testing.assert_allclose(lookup_batch(linear, 0, centres, srgb=False), expected, atol=1e-15)
    nearest = pack_textures([ImageTexture(pixels, filter="nearest")])
    off_centre = centres + np.array([0.2 / 4, -0.3 / 3])
    np.testing.assert_array_equal(lookup_batch(nearest, 0, off_centre, srgb=False), expected)


def test_8_bit_colour_is_decoded_by_the_srgb_curve_before_filtering():
    codes = np.array([[[0, 64, 128, 255], [255, 200, 10, 0]]], np.uint8)  # one row, two texels
    table = pack_textures([ImageTexture(codes, wrap="clamp")])
    centre = lookup_batch(table, 0, [[0.25, 0.5]], srgb=True)[0]
    x = np.array([0, 64, 128]) / 255.0
    srgb = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(centre[:3], srgb, rtol=1e-15)
    assert centre[3] == 1.0  # alpha stays linear
    midway = lookup_batch(table, 0, [[0.5, 0.5]], srgb=True)[0]
    np.testing.assert_allclose(midway[:3], 0.5 * (SRGB_TABLE[codes[0, 0, :3]] + SRGB_TABLE[codes[0, 1, :3]]))
    # the decoded curve's two ends and its middle (IEC 61966-2-1)
    assert SRGB_TABLE[0] == 0.0 and SRGB_TABLE[255] == 1.0 and SRGB_TABLE[128] == pytest.approx(0.2158605, abs=1e-7)


def test_storage_grey_and_alpha_expansion_and_memory():
    grey = ImageTexture(np.full((4, 6), 7, np.uint8))
    assert grey.pixels.shape == (4, 6, 4) and grey.pixels[0, 0].tolist() == [7, 7, 7, 255]
    assert grey.nbytes == 4 * 6 * 4 and not grey.is_float
    grey_alpha = ImageTexture(np.stack([np.full((2, 2), 0.3), np.full((2, 2), 0.6)], axis=-1))
    assert grey_alpha.is_float and grey_alpha.pixels[1, 1].tolist() == pytest.approx([0.3, 0.3, 0.3, 0.6])
    assert grey_alpha.nbytes == 2 * 2 * 16
    table = pack_textures([grey, grey_alpha, ImageTexture(np.zeros((1, 1, 3), np.uint8))])
    # stored in 4 x 4 tiles, padded: 4 x 6 -> 2 tiles (32 rows), 2 x 2 and 1 x 1 -> one tile each
    assert table.table[:, 0].tolist() == [0, 0, 32]  # offsets into the byte and float texels
    assert table.bytes.shape == (48, 4) and table.floats.shape == (16, 4)
    # the tiled order: texel (i, j) = (5, 2) of the 4 x 6 image is in tile 1, at row 2, column 1 of it
    marked = np.zeros((4, 6, 4), np.uint8)
    marked[2, 5] = 9
    assert np.nonzero(pack_textures([ImageTexture(marked)]).bytes[:, 0])[0].tolist() == [16 + 2 * 4 + 1]


def test_huge_and_non_finite_coordinates_stay_in_the_texture():
    table = pack_textures([ImageTexture(np.arange(12, dtype=np.float32).reshape(3, 4), wrap="repeat")])
    out = lookup_batch(table, 0, [[1e300, -1e300], [np.nan, 0.5], [np.inf, 1.0]], srgb=False)
    assert np.all(np.isfinite(out)) and np.all((out >= 0) & (out <= 11))


@pytest.mark.parametrize(
    ("pixels", "options", "message"),
    [
        (np.zeros((2, 2, 5)), {}, r"\(H, W\) or \(H, W, 1..4\)"),
        (np.zeros(4), {}, r"\(H, W\) or \(H, W, 1..4\)"),
        (np.full((2, 2), np.nan), {}, "NaN or infinite"),
        (np.zeros((2, 2)), {"wrap": "wrap"}, "wrap must be one of repeat, mirrored_repeat, clamp"),
        (np.zeros((2, 2)), {"filter": "cubic"}, "filter must be 'linear' or 'nearest'"),
        (np.array([["a"]]), {}, "must be numbers"),
    ],
)
def test_bad_textures_are_refused_in_one_line(pixels, options, message):
    with pytest.raises(ParameterError, match=message) as info:
        ImageTexture(pixels, name="albedo.png", **options)
    assert str(info.value).startswith("albedo.png: ") and "\n" not in str(info.value)


def test_files_8_and_16_bit_odd_sizes_and_corrupt_ones(tmp_path):
    import OpenImageIO as oiio

    rng = np.random.default_rng(5)
    for name, dtype, fmt in (("a.png", np.uint8, oiio.UINT8), ("b.png", np.uint16, oiio.UINT16)):
        top = np.iinfo(dtype).max
        data = rng.integers(0, top + 1, size=(3, 5, 3)).astype(dtype)
        out = oiio.ImageOutput.create(str(tmp_path / name))
        out.open(str(tmp_path / name), oiio.ImageSpec(5, 3, 3, fmt))
        out.write_image(data)
        out.close()
        texture = ImageTexture.read(tmp_path / name)
        assert (texture.width, texture.height) == (5, 3)
        if dtype is np.uint8:
            assert not texture.is_float and np.array_equal(texture.pixels[:, :, :3], data)
        else:  # 16 bits keep their precision as float32
            assert texture.is_float
            np.testing.assert_allclose(texture.pixels[:, :, :3], data / top, atol=1e-7)
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    with pytest.raises(ImageError, match=r"bad\.png: cannot read image") as info:
        ImageTexture.read(tmp_path / "bad.png")
    assert "\n" not in str(info.value)
    with pytest.raises(ImageError, match=r"none\.png: no such file"):
        ImageTexture.read(tmp_path / "none.png")
