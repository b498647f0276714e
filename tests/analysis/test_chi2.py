"""The chi-square machinery itself: pooling, outright failures, Sidak correction, quadrature."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.analysis import chi2


def test_passes_on_exact_multinomial_draws():
    rng = np.random.default_rng(0)
    p = rng.random(500) ** 4
    p /= p.sum()
    counts = rng.multinomial(100_000, p)
    assert chi2.goodness_of_fit(counts, 100_000 * p).passed


def test_fails_on_a_biased_distribution():
    rng = np.random.default_rng(0)
    p = np.full(100, 0.01)
    q = p.copy()
    q[:50] *= 1.05
    q /= q.sum()
    assert not chi2.goodness_of_fit(rng.multinomial(200_000, q), 200_000 * p).passed


def test_outright_failures():
    res = chi2.goodness_of_fit(np.array([10, 0, 5]), np.array([10.0, 5.0, 0.0]))
    assert not res.passed and "integrates to 0" in res.message
    res = chi2.goodness_of_fit(np.array([10, 10]), np.array([11.0, 11.0]))
    assert not res.passed and "> 1" in res.message
    assert not chi2.goodness_of_fit(np.zeros(3), np.ones(3)).passed


def test_sidak_correction():
    res = chi2.goodness_of_fit(np.array([50, 50]), np.array([50.0, 50.0]), alpha=0.01, test_count=10)
    assert res.alpha == pytest.approx(1 - 0.99**0.1)


def test_adaptive_quadrature_resolves_a_narrow_spike():
    """A cap of 0.1 degree inside one cell covering the sphere.  No quadrature node lands in it at first, so
    plain refinement sees 0 = 0 and stops; ``refine`` (set where samples fell) keeps looking until it is found,
    then refinement resolves its edge."""
    cos_max = np.cos(np.radians(0.1))
    axis = np.array([0.3, 0.4, np.sqrt(0.75)])

    def pdf(v):
        return np.where(v @ axis >= cos_max, 1.0 / (2 * np.pi * (1 - cos_max)), 0.0)

    cell = (np.array([0.0, np.pi]), np.array([0.0, 2 * np.pi]))
    blind = chi2.spherical_expected(pdf, *cell, max_depth=14, subdivisions=8, rtol=1e-7).sum()
    assert blind == 0.0
    total = chi2.spherical_expected(
        pdf, *cell, max_depth=16, subdivisions=8, rtol=1e-7, refine=np.ones((1, 1), bool), refine_depth=12
    ).sum()
    assert total == pytest.approx(1.0, abs=2e-3)


def test_non_unit_directions_fail():
    res = chi2.spherical_test(np.array([[0.0, 0.0, 2.0]] * 10), lambda v: np.full(len(v), 1 / (4 * np.pi)))
    assert not res.passed and "unit" in res.message


def test_cell_integrals_match_their_closed_forms_in_a_turned_frame():
    """pdf = (1 + x + z^2) / (4 pi + 4 pi / 3) in a random frame's local axes, over uneven cells: each cell's
    integral of pdf sin(theta) in closed form (the x term: sin(theta) cos(phi) against sin(theta), the z^2 term:
    cos^2 against sin)."""
    frame = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    norm = 4 * np.pi + 4 * np.pi / 3

    def pdf(v):
        local = v @ frame.T
        return (1.0 + local[:, 0] + local[:, 2] ** 2) / norm

    theta = np.array([0.0, 0.05, 0.4, 1.3, 2.0, 3.0, np.pi])
    phi = np.array([0.0, 0.7, 2.5, 2.6, 5.0, 2 * np.pi])
    t0, t1 = theta[:-1, None], theta[1:, None]
    p0, p1 = phi[None, :-1], phi[None, 1:]
    constant = (np.cos(t0) - np.cos(t1)) * (p1 - p0)
    x_term = (0.5 * (t1 - t0) - 0.25 * (np.sin(2 * t1) - np.sin(2 * t0))) * (np.sin(p1) - np.sin(p0))
    z2_term = (np.cos(t0) ** 3 - np.cos(t1) ** 3) / 3 * (p1 - p0)
    expected = (constant + x_term + z2_term) / norm
    got = chi2.spherical_expected(pdf, theta, phi, frame=frame, subdivisions=4, max_depth=0)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-15)
    assert got.sum() == pytest.approx(1.0, abs=1e-10)
    with pytest.raises(ValueError, match="returned 1 values for"):
        chi2.spherical_expected(lambda v: np.ones(1), theta, phi, max_depth=0)


def test_directions_are_counted_in_the_cells_of_their_angles_in_a_turned_frame():
    """Each direction lands in the cell of its (theta, phi) in the frame's local axes: directions at known cell
    centres; a direction exactly on an inner edge belongs to the cell above it (NumPy's ``searchsorted(side=
    "right")``); the poles and phi = 0 fall in the first and last cells."""
    rng = np.random.default_rng(4)
    frame = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    theta = np.array([0.0, 0.05, 0.4, 1.3, 2.0, 3.0, np.pi])
    phi = np.array([0.0, 0.7, 2.5, 2.6, 5.0, 2 * np.pi])
    expected = rng.integers(0, 4, size=(theta.size - 1, phi.size - 1)).astype(float)
    ti, pi = np.nonzero(expected)
    ti, pi = np.repeat(ti, expected[ti, pi].astype(int)), np.repeat(pi, expected[ti, pi].astype(int))
    t = 0.5 * (theta[ti] + theta[ti + 1])
    p = 0.5 * (phi[pi] + phi[pi + 1])
    local = np.column_stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    np.testing.assert_array_equal(chi2.spherical_counts(local @ frame, theta, phi, frame=frame), expected)

    # a direction exactly on an inner edge of both angles: theta = acos(0) and phi = atan2(1, 0) are pi / 2 exactly
    on_edges = chi2.spherical_counts(np.array([[0.0, 1.0, 0.0]]), [0.0, np.pi / 2, np.pi], [0.0, np.pi / 2, 2 * np.pi])
    np.testing.assert_array_equal(on_edges, [[0, 0], [0, 1]])
    poles = chi2.spherical_counts(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]), theta, phi)
    assert poles[0, 0] == 1 and poles[-1, 0] == 1 and poles[3, 0] == 1 and poles.sum() == 3
