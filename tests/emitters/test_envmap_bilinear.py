"""The bilinear environment density (pdf="bilinear"): what it is proportional to, and why it is the default.

Its chi-square, pdf-integral and sample-pdf tests run with the other PDF options in test_envmap.py."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.color import LUMINANCE_WEIGHTS
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.envmap_bilinear import (
    SMALL_ANGLE_COLUMNS,
    SMALL_ANGLE_ROWS,
    angle_tables,
    node_sines,
    sample_angles,
)
from lightprobe.emitters.procedural import sky_with_sun
from lightprobe.errors import ParameterError


def _directions(u, v):
    theta, phi = np.broadcast_arrays(np.pi * v, 2 * np.pi * u)
    return np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], axis=-1)


def test_node_sines_are_hat_means_of_sin_theta():
    s = node_sines(5)  # nodes at v = 0, 1/4, ..., 1
    v = np.linspace(0.0, 1.0, 200_001)
    for j in range(5):
        hat = np.clip(1.0 - np.abs(v - j / 4) * 4, 0.0, None)
        assert s[j] == pytest.approx(np.trapezoid(hat * np.sin(np.pi * v), v) / np.trapezoid(hat, v), rel=1e-6)
    assert node_sines(2) == pytest.approx([2 / np.pi, 2 / np.pi])  # a two-row map keeps a density at its poles
    assert node_sines(1).shape == (2,)


@pytest.mark.parametrize(("ny", "w"), [(SMALL_ANGLE_ROWS, SMALL_ANGLE_COLUMNS), (512, 1024), (4096, 8192)])
def test_sample_angles_are_libms_to_rounding(ny, w):
    """A sample's angles from the node tables and small-angle polynomials (no libm in the kernel) agree with
    cos(theta), sin(phi), cos(phi) computed directly, to within the rounding of the angle itself (phi up to 2 pi:
    2e-15), at the smallest tables the renderer uses them for and at 8K; the 0.05-rad bound on the small angle is
    what the thresholds guarantee."""
    assert np.pi / (SMALL_ANGLE_ROWS - 1) <= 0.05 and 2 * np.pi / SMALL_ANGLE_COLUMNS <= 0.05
    rows, columns = angle_tables(ny, w)
    rng = np.random.default_rng(5)
    for _ in range(2000):
        row, column = int(rng.integers(ny - 1)), int(rng.integers(w))
        t, tx = rng.random(2)
        t, tx = (1.0, 1.0) if _ == 0 else (t, tx)  # the cells' far corners: the largest small angles
        cos_theta, sin_phi, cos_phi = sample_angles(rows, columns, row, t, column, tx)
        theta, phi = np.pi * (row + t) / (ny - 1), 2 * np.pi * (column + 0.5 + tx) / w
        assert abs(cos_theta - np.cos(theta)) < 2e-15
        assert abs(sin_phi - np.sin(phi)) < 2e-15 and abs(cos_phi - np.cos(phi)) < 2e-15


@pytest.mark.parametrize("rotation", [None, 37.0])
def test_density_is_the_lookups_bilinear_luminance_times_the_node_sines(rotation):
    """Independently of the density's code: a map whose texels are luminance x s_j, looked up bilinearly (the
    lookup is checked against Mitsuba's placement elsewhere), must be proportional to p(w) x sin(theta)."""
    image = np.random.default_rng(3).random((6, 10, 3)).astype(np.float32) + 0.05
    env = EnvironmentMap.from_array(image, rotation=rotation)
    lum = image @ np.asarray(LUMINANCE_WEIGHTS, np.float32)
    weighted = (lum * node_sines(6)[:, None]).astype(np.float32)
    reference = EnvironmentMap.from_array(np.repeat(weighted[:, :, None], 3, axis=2), rotation=rotation)
    rng = np.random.default_rng(4)
    local = _directions(rng.random(5000), rng.uniform(0.01, 0.99, 5000))
    dirs = local @ env.to_world.T
    sin_theta = np.sqrt(1.0 - local[:, 1] ** 2)
    ratio = env.pdf(dirs) * sin_theta / reference.eval(dirs)[:, 0]
    np.testing.assert_allclose(ratio, ratio.mean(), rtol=1e-5)


def test_the_suns_radiance_over_its_density_is_nearly_constant():
    """The reason for the default: on a bilinearly looked-up sun, L / p -- the light estimator -- varies by 0.1 %
    with the bilinear density and by 32 % (a factor 19 end to end) with the 2x piecewise-constant grid."""
    image = sky_with_sun(1024, 512)
    u = np.random.default_rng(0).random((100_000, 2))
    spread = {}
    for pdf in ("bilinear", "exact"):
        env = EnvironmentMap.from_array(image, pdf=pdf)
        dirs, p = env.sample(u)
        lum = env.eval(dirs) @ np.asarray(LUMINANCE_WEIGHTS)
        sun = lum > 0.05 * lum.max()
        assert sun.sum() > 20_000  # most samples go to the sun
        ratio = lum[sun] / p[sun]
        spread[pdf] = ratio.std() / ratio.mean()
    assert spread["bilinear"] < 0.005
    assert spread["exact"] > 0.1


def test_constant_map_compensation_is_the_plain_density():
    env = EnvironmentMap.from_array(np.ones((8, 16, 3), np.float32))
    assert env.compensated_distribution is env.distribution
    dirs = _directions(*np.random.default_rng(5).random((2, 100)))
    np.testing.assert_array_equal(env.pdf(dirs, compensated=True), env.pdf(dirs))


def test_compensation_removes_the_mean_and_keeps_the_sun():
    env = EnvironmentMap.from_array(sky_with_sun(256, 128))
    rng = np.random.default_rng(6)
    ground = _directions(rng.random(1000), rng.uniform(0.6, 1.0, 1000))  # luminance ~0.1, below the map's mean
    assert np.all(env.pdf(ground) > 0.0)
    assert np.all(env.pdf(ground, compensated=True) == 0.0)
    u = rng.random((20_000, 2))
    sun = {}
    for compensated in (False, True):
        dirs, p = env.sample(u, compensated=compensated)
        assert p.min() > 0.0
        lum = env.eval(dirs) @ np.asarray(LUMINANCE_WEIGHTS)
        sun[compensated] = np.mean(lum > 100 * env.mean_luminance)
    assert sun[True] > sun[False] > 0.2


def test_defaults_follow_the_lookup_and_the_piecewise_options():
    env = EnvironmentMap.from_array(np.ones((4, 8, 3), np.float32))
    assert env.pdf_mode == "bilinear"
    assert "pdf='bilinear'" in repr(env) and "pdf_resolution" not in repr(env)  # the grid options do not apply
    assert EnvironmentMap.from_array(np.ones((4, 8, 3), np.float32), lookup="nearest").pdf_mode == "exact"
    for option in ({"pdf_resolution": 2}, {"pdf_weights": "blur"}):  # asking for a piecewise-constant PDF's option
        assert EnvironmentMap.from_array(np.ones((4, 8, 3), np.float32), **option).pdf_mode == "exact"
        with pytest.raises(ParameterError, match="pdf='bilinear'"):
            EnvironmentMap.from_array(np.ones((4, 8, 3), np.float32), pdf="bilinear", **option)


def test_pdf_image_is_the_density_at_texel_centres():
    env = EnvironmentMap.from_array(sky_with_sun(64, 32), rotation=20.0)
    image = env.pdf_image()
    assert image.shape == (32, 64)
    v, u = (np.arange(32) + 0.5) / 32, (np.arange(64) + 0.5) / 64
    local = _directions(u[None, :], v[:, None]).reshape(-1, 3)
    np.testing.assert_allclose(image.reshape(-1), env.pdf(local @ env.to_world.T), rtol=1e-12)
