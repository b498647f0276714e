"""Environment map: importance sampling proven against its own pdf, lookup conventions, input hygiene."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from lightprobe.analysis import chi2
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.mappings import direction_to_latlong
from lightprobe.emitters.procedural import constant, sky_with_sun
from lightprobe.errors import ImageError, LightprobeWarning, ParameterError
from lightprobe.images import write_image

from ..conftest import load_quietly, real_envmap_paths, requires_data


def one_hot(h=8, w=16, row=3, col=5):
    img = np.zeros((h, w, 3), np.float32)
    img[row, col] = 1.0
    return img


SYNTHETIC = {
    "one-hot": one_hot(),
    "constant": constant(2.0, width=32, height=16),
    "3x2": np.random.default_rng(0).random((2, 3, 3)).astype(np.float32),
    "1x1": np.ones((1, 1, 3), np.float32),
    "sun": sky_with_sun(1024, 512),  # 0.5-degree sun, ~1e5 x the sky
}
OPTIONS = {
    "bilinear": {},  # the default
    "bilinear-rotated": {"pdf": "bilinear", "rotation": 37.0},
    "exact": {"pdf": "exact"},
    "pbrt": {"pdf": "pbrt"},
    "exact-blur-1": {"pdf": "exact", "pdf_weights": "blur", "pdf_resolution": 1},
    "pbrt-bilinear-4": {"pdf": "pbrt", "pdf_weights": "bilinear", "pdf_resolution": 4},
    "exact-nearest": {"pdf": "exact", "lookup": "nearest"},  # no blur: the texel-exact distribution itself
    "pbrt-nearest-rotated": {"pdf": "pbrt", "lookup": "nearest", "rotation": 37.0},
}
# the 4x finer pdf grid of the 1024x512 sun map would take 30 s per test: its option is tested on the small maps
CASES = [(m, o, c) for m in SYNTHETIC for o in OPTIONS for c in (False, True) if (m, o) != ("sun", "pbrt-bilinear-4")]
N_CHI2 = len(CASES) + 3 * len(real_envmap_paths())


def make(name, option):
    return EnvironmentMap.from_array(SYNTHETIC[name], **OPTIONS[option])


@pytest.mark.parametrize(("name", "option", "compensated"), CASES)
def test_chi2_synthetic(name, option, compensated):
    env = make(name, option)
    result = chi2.check_envmap_sampling(env, compensated=compensated, test_count=N_CHI2)
    assert result.passed, str(result)
    assert result.pdf_integral == pytest.approx(1.0, abs=1e-4)


# each real map is tested with one of these in turn (every one of them on two or more maps): three per map made
# this the suite's costliest test group on a cold CI machine
REAL_MAP_VARIANTS = (
    ({}, False),
    ({}, True),
    ({"pdf": "exact", "rotation": 90.0}, True),
    ({"pdf": "pbrt", "rotation": 90.0}, False),
)


@requires_data
@pytest.mark.data
@pytest.mark.parametrize(
    ("path", "variant"),
    [(p, REAL_MAP_VARIANTS[i % len(REAL_MAP_VARIANTS)]) for i, p in enumerate(real_envmap_paths())],
    ids=lambda v: v.name if hasattr(v, "name") else str(v),
)
def test_chi2_real_maps(path, variant):
    options, compensated = variant
    env = load_quietly(path, **options)
    result = chi2.check_envmap_sampling(env, compensated=compensated, test_count=N_CHI2)
    assert result.passed, f"{options} compensated={compensated}: {result}"


@pytest.mark.parametrize("name", list(SYNTHETIC))
@pytest.mark.parametrize("option", list(OPTIONS))
def test_sample_pdf_matches_pdf_and_round_trip(name, option):
    env = make(name, option)
    u = np.random.default_rng(1).random((50_000, 2))
    for compensated in (False, True):
        dirs, pdf = env.sample(u, compensated=compensated)
        np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
        assert np.all(pdf > 0)
        np.testing.assert_allclose(env.pdf(dirs, compensated=compensated), pdf, rtol=1e-9)
        np.testing.assert_allclose(env.to_square(dirs, compensated=compensated), u, atol=1e-6)


@pytest.mark.parametrize("name", list(SYNTHETIC))
def test_pdf_integrates_to_one(name):
    for option in OPTIONS:
        if (name, option) == ("sun", "pbrt-bilinear-4"):
            continue  # 4096 x 2048 cells: covered on the small maps
        env = make(name, option)
        frame = chi2.ENV_TO_LATLONG_ANGLES @ env.to_world.T
        # order 2: a 2-point Gauss rule is exact for cubics, so for pdf x sin(theta) bilinear on each piece, and
        # for a product of a constant and sin(theta) on the parts below to about (part width)^4 / 4320, 1e-14
        if env.pdf_mode == "bilinear":
            theta, phi = env.pdf_pieces()
            total = chi2.spherical_expected(env.pdf, theta, phi, frame=frame, order=2, max_depth=0).sum()
            assert total == pytest.approx(1.0, abs=1e-6), option
            continue
        w, h = env.pdf_grid
        rows, cols = (h * max(1, 16 // h), w * max(1, 16 // w)) if h < 128 else (128, 256)
        theta = chi2.texel_edges(h, rows, np.pi)
        phi = chi2.texel_edges(w, cols, 2 * np.pi)
        # parts aligned with the pdf grid: a constant (x sin theta) per part
        total = chi2.spherical_expected(
            env.pdf, theta, phi, frame=frame, order=2, max_depth=0, subdivisions=max(1, h // rows)
        ).sum()
        assert total == pytest.approx(1.0, abs=1e-6), option
    # the per-cell picture integrates to one too (exact mode: constant per cell of the pdf grid)
    env = make(name, "exact")
    w, h = env.pdf_grid
    cell = 2 * np.pi / w * (np.cos(np.pi * np.arange(h) / h) - np.cos(np.pi * np.arange(1, h + 1) / h))
    assert np.sum(env.pdf_image() * cell[:, None]) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("name", ["3x2", "sun", "one-hot"])
def test_exact_pdf_is_proportional_to_texel_luminance(name):
    """Nearest lookup + exact pdf: L(w)/p(w) is the same for every sample of a grey map (zero variance)."""
    grey = np.repeat(SYNTHETIC[name].mean(axis=2, keepdims=True), 3, axis=2)
    env = EnvironmentMap.from_array(grey, lookup="nearest", pdf="exact", pdf_resolution=1)
    dirs, pdf = env.sample(np.random.default_rng(2).random((100_000, 2)))
    ratio = env.eval(dirs)[:, 0] / pdf
    np.testing.assert_allclose(ratio, env.integral(), rtol=1e-5)


def test_chi2_sees_sampling_at_texel_centres():
    """A test must be able to fail: returning the texel centre (Krivanek's 'usually sufficient' shortcut) fails."""
    env = EnvironmentMap.from_array(SYNTHETIC["3x2"], lookup="nearest", pdf_resolution=1)
    u = np.random.default_rng(3).random((1_000_000, 2))
    dirs, _ = env.sample(u)
    uv = np.array([direction_to_latlong(*d) for d in dirs[:2]])  # compile check of the kernel from Python
    assert uv.shape == (2, 2)
    w, h = env.resolution
    # snap every sample to its texel centre in (phi, theta)
    phi = np.mod(np.arctan2(dirs[:, 0], -dirs[:, 2]), 2 * np.pi)
    theta = np.arccos(np.clip(dirs[:, 1], -1, 1))
    phi_c = (np.floor(phi / (2 * np.pi) * w) + 0.5) * 2 * np.pi / w
    theta_c = (np.floor(theta / np.pi * h) + 0.5) * np.pi / h
    centred = np.stack([np.sin(phi_c) * np.sin(theta_c), np.cos(theta_c), -np.cos(phi_c) * np.sin(theta_c)], 1)
    frame = chi2.ENV_TO_LATLONG_ANGLES
    result = chi2.spherical_test(
        centred + 1e-9,
        env.pdf,
        frame=frame,
        theta_edges=chi2.texel_edges(h, 32, np.pi),
        phi_edges=chi2.texel_edges(w, 63, 2 * np.pi),
        order=2,
    )
    assert not result.passed


def test_chi2_sees_pbrt_samples_against_the_exact_pdf():
    """The two pdf modes differ only inside texels (sin(theta) vs uniform in cos(theta)); the test resolves it."""
    pbrt = EnvironmentMap.from_array(SYNTHETIC["3x2"], pdf="pbrt", pdf_resolution=1)
    exact = EnvironmentMap.from_array(SYNTHETIC["3x2"], pdf="exact", pdf_resolution=1)
    dirs, _ = pbrt.sample(np.random.default_rng(4).random((1_000_000, 2)))
    result = chi2.spherical_test(
        dirs,
        exact.pdf,
        frame=chi2.ENV_TO_LATLONG_ANGLES,
        theta_edges=chi2.texel_edges(2, 32, np.pi),
        phi_edges=chi2.texel_edges(3, 63, 2 * np.pi),
        order=2,
    )
    assert not result.passed


# --- conventions --------------------------------------------------------------------------------------------------
def quadrant_map():
    """Four columns: u in [0, .25) red, [.25, .5) green, [.5, .75) blue, [.75, 1) white."""
    img = np.zeros((2, 4, 3), np.float32)
    img[:, 0] = (1, 0, 0)
    img[:, 1] = (0, 1, 0)
    img[:, 2] = (0, 0, 1)
    img[:, 3] = (1, 1, 1)
    return img


def test_latlong_convention_is_mitsubas():
    """u = atan2(x, -z)/(2 pi): u = 0 is -Z, 0.25 is +X, 0.5 is +Z, 0.75 is -X; v = acos(y)/pi, row 0 = +Y."""
    cases = {(0, 0, -1): (0.0, 0.5), (1, 0, 0): (0.25, 0.5), (0, 0, 1): (0.5, 0.5), (-1, 0, 0): (0.75, 0.5)}
    for d, uv in cases.items():
        assert direction_to_latlong(*map(float, d)) == pytest.approx(uv)
    assert direction_to_latlong(0.0, 1.0, 0.0)[1] == 0.0
    assert direction_to_latlong(0.0, -1.0, 0.0)[1] == 1.0
    env = EnvironmentMap.from_array(quadrant_map(), lookup="nearest")
    # just past each quarter boundary, rotating from -Z toward +X
    probes = [(math.sin(a), 0.0, -math.cos(a)) for a in np.radians([10, 100, 190, 280])]
    np.testing.assert_allclose(env.eval(np.array(probes)), [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)])


def test_bilinear_rows_are_corner_aligned_like_mitsuba():
    rows = np.array([1.0, 2.0, 4.0, 8.0, 16.0], np.float32)
    img = np.repeat(np.repeat(rows[:, None, None], 6, axis=1), 3, axis=2)
    env = EnvironmentMap.from_array(img)
    h = len(rows)
    for j in range(h):
        theta = math.pi * j / (h - 1)  # row j sits exactly at v = j/(H-1)
        d = np.array([[math.sin(theta), math.cos(theta), 0.0]])
        assert env.eval(d)[0, 0] == pytest.approx(rows[j], rel=1e-6)
    mid = math.pi * 0.5 / (h - 1)
    assert env.eval(np.array([[math.sin(mid), math.cos(mid), 0.0]]))[0, 0] == pytest.approx(1.5, rel=1e-6)


def test_bilinear_columns_are_texel_centred_and_periodic():
    img = np.zeros((3, 4, 3), np.float32)
    img[:, 0] = 1.0  # column 0 centred at u = 1/8, wraps to column 3 (centred at u = 7/8)
    env = EnvironmentMap.from_array(img)

    def at(u):
        a = 2 * math.pi * u
        return env.eval(np.array([[math.sin(a), 0.0, -math.cos(a)]]))[0, 0]

    assert at(1 / 8) == pytest.approx(1.0)
    assert at(0.0) == pytest.approx(0.5)  # half way between column 3 (u = 7/8) and column 0 (u = 9/8)
    assert at(3 / 8) == pytest.approx(0.0, abs=1e-7)


def test_rotation_and_scale():
    img = SYNTHETIC["3x2"]
    base = EnvironmentMap.from_array(img)
    rotated = EnvironmentMap.from_array(img, rotation=30.0, scale=2.5)
    dirs = np.random.default_rng(5).normal(size=(1000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    a = math.radians(30.0)
    r = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    np.testing.assert_allclose(rotated.eval(dirs @ r.T), 2.5 * base.eval(dirs), rtol=1e-5)
    np.testing.assert_allclose(rotated.pdf(dirs @ r.T), base.pdf(dirs), rtol=1e-9)
    assert rotated.integral() == pytest.approx(2.5 * base.integral())
    matrix = EnvironmentMap.from_array(img, rotation=r)
    np.testing.assert_allclose(matrix.eval(dirs), rotated.eval(dirs) / 2.5, rtol=1e-5)


@pytest.mark.parametrize("lookup", ["bilinear", "nearest"])
def test_a_constant_map_is_looked_up_without_coordinates_and_sees_the_same(lookup):
    """A map whose every texel is the same radiance (a scene file's ``constant``) returns it, scaled, for every
    direction without its lat-long coordinates; one texel apart makes it an ordinary map, looked up as before."""
    dirs = np.random.default_rng(6).normal(size=(2000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    value = np.array([0.04, 0.05, 0.07], np.float32)
    flat = EnvironmentMap.from_array(np.broadcast_to(value, (4, 8, 3)).copy(), scale=2.5, lookup=lookup)
    assert flat.kernel.uniform
    np.testing.assert_array_equal(flat.eval(dirs), np.broadcast_to(value * np.float32(2.5), (2000, 3)))
    spot = np.broadcast_to(value, (4, 8, 3)).copy()
    spot[1, 2] = 1.0
    uneven = EnvironmentMap.from_array(spot, scale=2.5, lookup=lookup)
    assert not uneven.kernel.uniform
    seen = uneven.eval(dirs)
    assert seen.max() > 1.0 and seen.min() == pytest.approx(2.5 * 0.04, rel=1e-6)


# --- angular (Debevec) mapping -----------------------------------------------------------------------------------
def test_angular_mapping_follows_the_seed():
    from lightprobe.emitters.mappings import angular_to_direction, direction_to_angular

    rng = np.random.default_rng(6)
    for d in rng.normal(size=(200, 3)):
        d = d / np.linalg.norm(d)
        s, t = direction_to_angular(*d)
        # the seed's snippet, with the row measured from the top (+Y up)
        r = 0.159154943 * math.acos(d[2]) / math.hypot(d[0], d[1])
        assert (s, t) == pytest.approx((0.5 + d[0] * r, 0.5 - d[1] * r), abs=1e-8)
        x, y, z, inside = angular_to_direction(s, t)
        assert inside
        assert (x, y, z) == pytest.approx(tuple(d), abs=1e-7)
    assert direction_to_angular(0.0, 0.0, 1.0) == (0.5, 0.5)  # centre: +Z
    assert direction_to_angular(0.0, 1.0, 0.0) == pytest.approx((0.5, 0.25))  # +Y toward the top
    assert direction_to_angular(1.0, 0.0, 0.0) == pytest.approx((0.75, 0.5))  # +X to the right


def test_angular_round_trip_preserves_the_light():
    latlong = sky_with_sun(256, 128, sun_radiance=(50.0, 50.0, 50.0), sun_diameter_deg=8.0)
    env = EnvironmentMap.from_array(latlong)
    angular = env.to_array(mapping="angular", size=512)
    back = EnvironmentMap.from_array(angular, mapping="angular")
    assert back.resolution == (512, 256)
    assert back.integral() == pytest.approx(env.integral(), rel=0.01)
    sun = np.array([[0.579228, 0.573576, -0.579228]])
    assert back.eval(sun)[0, 0] > 0.5 * env.eval(sun)[0, 0]


def test_angular_map_must_be_square():
    with pytest.raises(ImageError, match="square"):
        EnvironmentMap.from_array(np.ones((4, 8, 3)), mapping="angular")


# --- input hygiene ------------------------------------------------------------------------------------------------
def test_nan_is_rejected_naming_the_file(tmp_path):
    img = np.ones((4, 8, 3), np.float32)
    img[1, 2, 0] = np.nan
    path = write_image(tmp_path / "nan.exr", img)
    with pytest.raises(ImageError, match=r"nan\.exr: 1 texels are NaN or infinite"):
        EnvironmentMap.load(path)


def test_infinity_is_rejected():
    img = np.ones((4, 8, 3), np.float32)
    img[0, 0] = np.inf
    with pytest.raises(ImageError, match="infinite"):
        EnvironmentMap.from_array(img)


def test_negative_values_are_clamped_with_a_warning():
    img = np.ones((4, 8, 3), np.float32)
    img[2, 3, 1] = -0.5
    with pytest.warns(LightprobeWarning, match="clamped 1 negative"):
        env = EnvironmentMap.from_array(img, lookup="nearest")
    assert env.radiance.min() == 0.0


def test_black_map_is_rejected(tmp_path):
    path = write_image(tmp_path / "black.hdr", np.zeros((4, 8, 3), np.float32))
    with pytest.raises(ImageError, match="black everywhere"):
        EnvironmentMap.load(path)


@pytest.mark.parametrize("content", [b"", b"not an image at all", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X"])
def test_corrupt_files(tmp_path, content):
    path = tmp_path / "broken.hdr"
    path.write_bytes(content)
    with pytest.raises(ImageError, match=r"broken\.hdr"):
        EnvironmentMap.load(path)


def test_missing_file():
    with pytest.raises(ImageError, match="no such file"):
        EnvironmentMap.load("does/not/exist.exr")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"scale": 0.0}, "scale"),
        ({"scale": float("nan")}, "scale"),
        ({"lookup": "cubic"}, "lookup"),
        ({"pdf": "uniform"}, "pdf"),
        ({"rotation": np.diag([1.0, 1.0, -1.0])}, "rotation"),
        ({"rotation": "north"}, "rotation"),
        ({"mapping": "cube"}, "mapping"),
        ({"pdf_weights": "smooth"}, "pdf_weights"),
        ({"pdf_resolution": 0}, "pdf_resolution"),
        ({"pdf_resolution": 1.5}, "pdf_resolution"),
    ],
)
def test_bad_parameters(kwargs, match):
    with pytest.raises((ParameterError, ImageError), match=match):
        EnvironmentMap.from_array(np.ones((2, 4, 3)), **kwargs)


def test_channels():
    grey = EnvironmentMap.from_array(np.full((2, 4), 3.0), lookup="nearest")
    np.testing.assert_allclose(grey.eval(np.array([[0.0, 1.0, 0.0]])), [[3.0, 3.0, 3.0]])
    rgba = EnvironmentMap.from_array(np.ones((2, 4, 4)))
    assert rgba.radiance.shape == (2, 4, 3)
    with pytest.raises(ImageError, match="channels"):
        EnvironmentMap.from_array(np.ones((2, 4, 2)))


@requires_data
@pytest.mark.data
def test_stats_match_the_data_notes():
    """SOURCES.md lists mean luminance 0.649, 0.58 of the energy in the top 0.1 % and 21.5 stops for sunrise."""
    from lightprobe.data import named_envmap_path

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = EnvironmentMap.load(named_envmap_path("sunrise"))
    assert any("clamped 358 negative" in str(w.message) for w in caught)
    stats = env.stats()
    assert stats["mean_luminance"] == pytest.approx(0.649, abs=0.001)
    assert stats["top_0.1%_energy_fraction"] == pytest.approx(0.58, abs=0.01)
    assert stats["dynamic_range_stops"] == pytest.approx(21.5, abs=0.1)


# --- what a file can get wrong -------------------------------------------------------------------------------------
def _loud_load(path, **options):
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = EnvironmentMap.load(path, **options)
    return env, [str(w.message) for w in caught]


@pytest.mark.parametrize(
    ("width", "height", "warns"), [(96, 32, True), (64, 64, True), (64, 32, False), (65, 32, False)]
)
def test_a_latlong_map_that_is_not_two_to_one_warns(tmp_path, width, height, warns):
    from lightprobe.images import write_image

    path = write_image(tmp_path / f"map{width}x{height}.exr", np.ones((height, width, 3), np.float32))
    _, messages = _loud_load(path)
    aspect = [m for m in messages if "twice as wide" in m]
    assert bool(aspect) == warns, messages
    if warns:
        assert aspect[0].startswith(str(path)) and f"{width}x{height}" in aspect[0] and len(aspect) == 1
        assert _loud_load(path)[1] == []  # once per file


def test_a_non_square_angular_map_is_an_error_naming_the_file(tmp_path):
    from lightprobe.errors import ImageError
    from lightprobe.images import write_image

    path = write_image(tmp_path / "probe.exr", np.ones((32, 48, 3), np.float32))
    with pytest.raises(ImageError, match=r"probe.exr: an angular .* must be square .*, this one is 48x32"):
        EnvironmentMap.load(path, mapping="angular")


def test_an_srgb_png_map_is_linear_radiance_in_the_renderer_and_in_envmap_info(tmp_path, capsys):
    import json

    import OpenImageIO as oiio

    from lightprobe.cli import main

    codes = np.zeros((16, 32, 3), np.uint8)
    codes[:, :, 0], codes[:, :, 1], codes[:, :, 2] = 128, 255, 10
    path = tmp_path / "sky.png"
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(32, 16, 3, oiio.UINT8))
    out.write_image(codes)
    out.close()
    env, messages = _loud_load(path)
    assert len(messages) == 1 and "display-encoded" in messages[0] and "sRGB curve" in messages[0]
    linear = np.array([0.2158605, 1.0, 0.0030353])  # sRGB decoding of 128, 255, 10
    np.testing.assert_allclose(env.eval(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])), [linear, linear], rtol=1e-5)
    assert main(["envmap", "info", str(path), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["max_luminance"] == pytest.approx(env.stats()["max_luminance"], rel=1e-12)
    assert stats["max_luminance"] == pytest.approx(0.212671 * linear[0] + 0.715160 * linear[1] + 0.072169 * linear[2])


def test_each_warning_is_printed_once_per_file():
    """`envmap pdf` of a map with negative texels (and an odd aspect): each warning once, in a fresh process."""
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from lightprobe.images import write_image

    with tempfile.TemporaryDirectory() as folder:
        img = np.ones((32, 96, 3), np.float32)
        img[3, 3, 0] = -1.0
        path = write_image(Path(folder) / "neg.exr", img)
        for command in (["envmap", "pdf", str(path), "-o", str(Path(folder) / "p.png")], ["envmap", "info", str(path)]):
            run = subprocess.run([sys.executable, "-m", "lightprobe", *command], capture_output=True, text=True)
            assert run.returncode == 0, run.stderr
            lines = run.stderr.strip().splitlines()
            assert sum("negative values" in line for line in lines) == 1, lines
            assert sum("twice as wide" in line for line in lines) == 1, lines
            assert all(line.startswith("lightprobe: warning:") for line in lines), lines
