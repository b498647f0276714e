"""Piecewise-constant 1D and 2D distributions: exact cell probabilities, round trips, degenerate inputs."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.analysis.chi2 import goodness_of_fit
from lightprobe.sampling import PiecewiseConstant1D, PiecewiseConstant2D

N = 500_000


def _split(func, k):
    """Histogram edges splitting every bin in k: the pdf is constant on each cell, so probabilities are exact."""
    return np.linspace(0.0, 1.0, func.size * k + 1)


@pytest.mark.parametrize(
    "func",
    [np.array([1.0]), np.array([0.0, 3.0, 1.0, 0.0, 5.0, 0.0]), np.r_[np.zeros(50), 1e-6, np.ones(49) * 1e3]],
    ids=["single-bin", "with-zeros", "tiny-and-huge"],
)
def test_1d_chi2_and_pdf(func):
    dist = PiecewiseConstant1D(func)
    u = np.random.default_rng(1).random(N)
    x, pdf, index = dist.sample(u)
    np.testing.assert_array_equal(pdf, dist.pdf(x))
    np.testing.assert_array_equal(index, np.minimum((x * func.size).astype(int), func.size - 1))
    edges = _split(func, 8)
    counts, _ = np.histogram(x, bins=edges)
    centres = 0.5 * (edges[1:] + edges[:-1])
    expected = N * dist.pdf(centres) * np.diff(edges)
    result = goodness_of_fit(counts, expected, test_count=3)
    assert result.passed, str(result)
    assert dist.integral == pytest.approx(func.mean())
    assert np.sum(dist.pdf(centres) * np.diff(edges)) == pytest.approx(1.0, abs=1e-12)


def test_1d_continuous_offset_and_inverse():
    dist = PiecewiseConstant1D([1.0, 0.0, 2.0, 1.0], domain=(-1.0, 3.0))
    u = np.linspace(0.0, 1.0, 1001)[:-1]
    x, pdf, _ = dist.sample(u)
    assert np.all(np.diff(x) >= 0), "the map from u to x must be monotonic (keeps stratification)"
    assert np.all((x < 0.0) | (x >= 1.0)), "the empty bin [0, 1) is never sampled"
    np.testing.assert_allclose(dist.invert(x), u, atol=1e-12)
    np.testing.assert_allclose(pdf, dist.pdf(x))
    assert dist.integral == pytest.approx(4.0)
    # the first bin [-1, 0) holds 1/4 of the mass, spread uniformly: u = 0.125 maps to its middle
    assert dist.sample([0.125])[0][0] == pytest.approx(-0.5)


def test_1d_all_zero_is_uniform_with_zero_integral():
    dist = PiecewiseConstant1D(np.zeros(4))
    assert dist.integral == 0.0
    x, pdf, _ = dist.sample(np.array([0.1, 0.6]))
    np.testing.assert_allclose(x, [0.1, 0.6])
    np.testing.assert_allclose(pdf, 1.0)


@pytest.mark.parametrize("bad", [[-1.0, 2.0], [np.nan, 1.0], [np.inf], []])
def test_1d_rejects_bad_values(bad):
    with pytest.raises(ValueError):
        PiecewiseConstant1D(bad)


FUNCS_2D = {
    "3x2": np.array([[1.0, 2.0, 3.0], [0.5, 0.0, 4.0]]),
    "zero-row": np.array([[1.0, 2.0], [0.0, 0.0], [3.0, 1.0]]),
    "one-hot": np.eye(1, 40).reshape(5, 8),
    "random": np.random.default_rng(4).random((16, 32)) ** 8,
}


@pytest.mark.parametrize("name", FUNCS_2D)
def test_2d_chi2_and_pdf(name):
    func = FUNCS_2D[name]
    dist = PiecewiseConstant2D(func)
    pts, pdf = dist.sample(np.random.default_rng(2).random((N, 2)))
    np.testing.assert_array_equal(pdf, dist.pdf(pts))
    ny, nx = func.shape
    ex, ey = _split(np.zeros(nx), 4), _split(np.zeros(ny), 4)
    counts, _, _ = np.histogram2d(pts[:, 1], pts[:, 0], bins=[ey, ex])
    cy, cx = 0.5 * (ey[1:] + ey[:-1]), 0.5 * (ex[1:] + ex[:-1])
    gx, gy = np.meshgrid(cx, cy)
    cell = np.outer(np.diff(ey), np.diff(ex))
    density = dist.pdf(np.stack([gx.ravel(), gy.ravel()], axis=1)).reshape(gx.shape)
    assert np.sum(density * cell) == pytest.approx(1.0, abs=1e-12)
    # the density is func / integral, up to the rounding of CDF differences: |error| <= a few n eps absolute
    np.testing.assert_allclose(density[::4, ::4], func / func.mean(), rtol=1e-9, atol=8 * nx * ny * 2.3e-16)
    result = goodness_of_fit(counts, N * density * cell, test_count=len(FUNCS_2D))
    assert result.passed, str(result)


def test_2d_round_trip():
    dist = PiecewiseConstant2D(FUNCS_2D["random"])
    u = np.random.default_rng(9).random((10_000, 2))
    pts, _ = dist.sample(u)
    np.testing.assert_allclose(dist.invert(pts), u, atol=1e-9)


def test_2d_all_zero_is_uniform():
    dist = PiecewiseConstant2D(np.zeros((2, 3)))
    assert dist.integral == 0.0
    pts, pdf = dist.sample(np.array([[0.5, 0.25]]))
    np.testing.assert_allclose(pts, [[0.5, 0.25]])
    np.testing.assert_allclose(pdf, 1.0)


@pytest.mark.parametrize("p", [0.0, 0.3, 0.5, 1.0 - 1e-9, 1.0])
def test_choose_rescaled_keeps_each_share_uniform(p):
    from lightprobe.sampling.distributions import choose_rescaled

    u = (np.arange(4096) + 0.5) / 4096  # evenly spaced: each option's rescaled numbers must be evenly spaced too
    chosen = np.array([choose_rescaled(x, p) for x in u])
    first, v = chosen[:, 0].astype(bool), chosen[:, 1]
    assert np.all((v >= 0.0) & (v < 1.0))
    assert first.sum() == np.count_nonzero(u < p)
    for share, lo, width in ((first, 0.0, p), (~first, p, 1.0 - p)):
        if share.any():
            np.testing.assert_allclose(v[share], (u[share] - lo) / width, rtol=1e-12)
            # uniform on [0, 1): the spread of an evenly spaced share (a share of one point sits anywhere)
            if share.sum() > 1:
                assert v[share].min() < 2.0 / share.sum() and v[share].max() > 1.0 - 2.0 / share.sum()
    if p > 0.0:  # just below p: the first option, rescaled to below 1 however u / p rounds
        first_below, v_below = choose_rescaled(np.nextafter(p, 0.0), p)
        assert first_below and v_below < 1.0
