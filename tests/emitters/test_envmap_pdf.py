"""The environment map's distributions, built in two passes, against a direct (point-by-point) construction."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.mappings import bilinear_latlong_weights
from lightprobe.sampling.distributions import PiecewiseConstant2D


def _bilinear_cell_means(lum: np.ndarray, f: int, k: int) -> np.ndarray:
    """Mean of the bilinear reconstruction over each cell of a grid f times finer, from k x k points per cell."""
    h, w = lum.shape
    out = np.zeros((h * f, w * f))
    for j in range(h * f):
        for i in range(w * f):
            acc = 0.0
            for a in range(k):
                v = (j + (a + 0.5) / k) / (h * f)
                for b in range(k):
                    u = (i + (b + 0.5) / k) / (w * f)
                    y0, y1, x0, x1, ty, tx = bilinear_latlong_weights(h, w, u, v)
                    top = (1 - tx) * lum[y0, x0] + tx * lum[y0, x1]
                    bottom = (1 - tx) * lum[y1, x0] + tx * lum[y1, x1]
                    acc += (1 - ty) * top + ty * bottom
            out[j, i] = acc / (k * k)
    return out


def _blur(lum: np.ndarray) -> np.ndarray:
    """pbrt's [1 2 1] x [1 2 1] / 16, periodic in u, edge-replicated in v."""
    horizontal = 0.25 * np.roll(lum, 1, axis=1) + 0.5 * lum + 0.25 * np.roll(lum, -1, axis=1)
    padded = np.concatenate([horizontal[:1], horizontal, horizontal[-1:]], axis=0)
    return 0.25 * padded[:-2] + 0.5 * padded[1:-1] + 0.25 * padded[2:]


def _refine(values: np.ndarray, f: int) -> np.ndarray:
    return np.repeat(np.repeat(values, f, axis=0), f, axis=1)


@pytest.mark.parametrize("weights", ["bilinear", "texel", "blur"])
@pytest.mark.parametrize("f", [1, 2, 4])
@pytest.mark.parametrize("pdf", ["exact", "pbrt"])
def test_distributions_match_a_direct_construction(weights, f, pdf):
    rng = np.random.default_rng(3)
    image = rng.random((6, 10, 3)).astype(np.float32) ** 4
    image[2, 7] = 300.0  # a sun
    env = EnvironmentMap.from_array(image, pdf=pdf, pdf_weights=weights, pdf_resolution=f)
    lum = env.luminance.astype(np.float64)
    if weights == "bilinear":
        cells = _bilinear_cell_means(lum, f, max(1, 4 // f)) + 1e-4 * _refine(_blur(lum), f)
    else:
        cells = _refine(_blur(lum) if weights == "blur" else lum, f)
    rows = lum.shape[0] * f
    edges = np.cos(np.pi * np.arange(rows + 1) / rows)
    factor = edges[:-1] - edges[1:] if pdf == "exact" else np.sin(np.pi * (np.arange(rows) + 0.5) / rows)
    solid_angle = (2 * np.pi / (lum.shape[1] * f)) * (edges[:-1] - edges[1:])
    mean = (cells * solid_angle[:, None]).sum() / (4 * np.pi)
    for dist, func in (
        (env.distribution, cells * factor[:, None]),
        (env.compensated_distribution, np.maximum(cells - mean, 0.0) * factor[:, None]),
    ):
        expected = PiecewiseConstant2D(func)
        assert dist.shape == expected.shape == (rows, lum.shape[1] * f)
        np.testing.assert_allclose(dist.marginal_cdf, expected.marginal_cdf, rtol=1e-5, atol=1e-12)
        np.testing.assert_allclose(dist.conditional_cdf, expected.conditional_cdf, rtol=1e-5, atol=1e-12)
        assert dist.integral == pytest.approx(expected.integral, rel=1e-5)


def test_constant_map_compensation_samples_like_the_plain_distribution():
    env = EnvironmentMap.from_array(np.ones((8, 16, 3), np.float32), pdf="exact")
    for name in ("conditional_cdf", "marginal_cdf"):
        plain, compensated = getattr(env.distribution, name), getattr(env.compensated_distribution, name)
        np.testing.assert_allclose(compensated, plain, rtol=1e-9, atol=1e-12)


def test_default_pdf_resolution_refines_small_maps_only():
    assert EnvironmentMap.from_array(np.ones((8, 16, 3), np.float32), pdf="exact").pdf_resolution == 2
    assert EnvironmentMap.from_array(np.ones((1025, 2050, 3), np.float32), pdf="pbrt").pdf_resolution == 1
