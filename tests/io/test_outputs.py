"""Render outputs: the EXR variance channels, every main format, the sidecar, and the checks before a render."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lightprobe.errors import ImageError
from lightprobe.images import read_image
from lightprobe.integrators.wavefront import RenderResult
from lightprobe.io.outputs import check_output, write_render


@pytest.fixture
def result():
    rng = np.random.default_rng(3)
    image = (rng.random((4, 5, 3)) * 3).astype(np.float32)
    variance = (rng.random((4, 5, 3)) * 1e-3).astype(np.float32)
    stats = {"spp_done": 7, "seconds": 1.5, "strategy": "mis", "samples_per_s": 93.3, "ratio": float("nan")}
    return RenderResult(image, variance, np.full((4, 5), 7), stats)


def test_exr_with_variance_has_named_channels_and_the_values(tmp_path, result):
    import OpenImageIO as oiio

    path = tmp_path / "r.exr"
    written = write_render(path, result, variance=True)
    assert written == [path, tmp_path / "r.exr.json"]
    spec = oiio.ImageInput.open(str(path)).spec()
    assert tuple(spec.channelnames) == ("R", "G", "B", "variance.R", "variance.G", "variance.B")
    data = read_image(path)
    np.testing.assert_array_equal(data[..., :3], result.image)
    np.testing.assert_array_equal(data[..., 3:], result.variance)


@pytest.mark.parametrize("ext", [".hdr", ".pfm", ".png"])
def test_every_main_format(tmp_path, result, ext):
    path = tmp_path / f"r{ext}"
    write_render(path, result, exposure=-2.0)
    back = read_image(path)
    assert back.shape[:2] == (4, 5)
    if ext == ".png":  # tone mapped: 2^-2 x the linear value, sRGB encoded, 8 bits
        x = np.clip(result.image * 0.25, 0, 1).astype(np.float64)
        expected = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
        np.testing.assert_allclose(back[..., :3], np.round(expected * 255) / 255, atol=1e-6)
    elif ext == ".pfm":
        np.testing.assert_array_equal(back, result.image)
    else:  # RGBE
        assert np.all(np.abs(back - result.image) <= result.image.max(axis=2, keepdims=True) / 128)


def test_sidecar_records_settings_and_replaces_nan_by_null(tmp_path, result):
    write_render(tmp_path / "r.exr", result, extra={"scene": "test"})
    meta = json.loads((tmp_path / "r.exr.json").read_text())
    assert meta["spp_done"] == 7 and meta["strategy"] == "mis" and meta["scene"] == "test"
    assert meta["ratio"] is None and meta["output"] == str(tmp_path / "r.exr") and meta["machine"]["cpus"] >= 1


def test_preview_png_beside_a_linear_output(tmp_path, result):
    written = write_render(tmp_path / "r.exr", result, png=tmp_path / "sub" / "p.png")
    assert tmp_path / "sub" / "p.png" in written and read_image(tmp_path / "sub" / "p.png").shape[:2] == (4, 5)


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("r.tiff", {}, "unsupported output format"),
        ("r", {}, "unsupported output format (none)"),
        ("r.png", {"variance": True}, "needs an .exr"),
        ("r.exr", {"png": "p.jpg"}, "must be a .png"),
        ("folder", {}, "unsupported"),
    ],
)
def test_check_output_errors(tmp_path, name, options, message):
    (tmp_path / "folder").mkdir()
    options = {k: (tmp_path / v if k == "png" else v) for k, v in options.items()}
    with pytest.raises(ImageError, match=message.replace("(", r"\(").replace(")", r"\)")):
        check_output(tmp_path / name, **options)


def test_check_output_refuses_a_folder_named_like_the_output(tmp_path):
    (tmp_path / "r.exr").mkdir()
    with pytest.raises(ImageError, match=r"r\.exr: is a folder"):
        check_output(tmp_path / "r.exr")


def test_check_output_makes_missing_folders_and_leaves_no_probe(tmp_path):
    check_output(tmp_path / "a" / "b" / "r.exr", resolution=(640, 400))
    assert (tmp_path / "a" / "b").is_dir() and list((tmp_path / "a" / "b").iterdir()) == []
