"""MIS heuristics: the formulas, weights summing to one, and safety on degenerate densities."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.sampling import balance_heuristic, power_heuristic


def test_balance_formula():
    assert balance_heuristic(2.0, 1.0) == pytest.approx(2 / 3)
    assert balance_heuristic(2.0, 1.0, n_f=1, n_g=4) == pytest.approx(2 / 6)


def test_power_formula():
    assert power_heuristic(2.0, 1.0) == pytest.approx(4 / 5)
    assert power_heuristic(2.0, 1.0, n_f=3, n_g=1) == pytest.approx(36 / 37)
    assert power_heuristic(2.0, 1.0, beta=3) == pytest.approx(8 / 9)


@pytest.mark.parametrize("heuristic", [balance_heuristic, power_heuristic])
def test_weights_sum_to_one(heuristic):
    rng = np.random.default_rng(0)
    p, q = 10.0 ** rng.uniform(-300, 300, 1000), 10.0 ** rng.uniform(-300, 300, 1000)
    total = heuristic(p, q, n_f=2, n_g=3) + heuristic(q, p, n_f=3, n_g=2)
    np.testing.assert_allclose(total, 1.0, rtol=1e-12)


@pytest.mark.parametrize("heuristic", [balance_heuristic, power_heuristic])
def test_degenerate_densities(heuristic):
    inf, nan = np.inf, np.nan
    p = np.array([0.0, 1.0, inf, inf, nan, 1.0, 1.0, 1e300])
    q = np.array([1.0, 0.0, 1.0, inf, 1.0, nan, inf, 1e300])
    w = heuristic(p, q)
    np.testing.assert_array_equal(w, [0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.5])
    assert np.all(np.isfinite(w))


def test_zero_sample_count():
    assert balance_heuristic(1.0, 1.0, n_f=0, n_g=1) == 0.0
    assert balance_heuristic(1.0, 1.0, n_f=1, n_g=0) == 1.0
    with pytest.raises(ValueError):
        balance_heuristic(1.0, 1.0, n_f=-1)
