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


@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_weight_over_and_share_are_the_weight_divided(beta):
    """The finish stage's forms w / (n_f p_f) and w / n_f. The balance heuristic's one division against exact
    rational arithmetic on densities from 1e-300 to 1e300 (where n_f p_f + n_g p_g overflows it takes mis_weight's
    ratio); the power heuristic and degenerate densities (those of the test above) as mis_weight divided."""
    from fractions import Fraction

    from lightprobe.sampling.mis import mis_weight, mis_weight_over, mis_weight_share

    rng = np.random.default_rng(3)
    inf, nan = np.inf, np.nan
    p = np.concatenate([10.0 ** rng.uniform(-300, 300, 2000), [0.0, 1.0, inf, inf, nan, 1.0, 1.0, 1e300, 1e308]])
    q = np.concatenate([10.0 ** rng.uniform(-300, 300, 2000), [1.0, 0.0, 1.0, inf, 1.0, nan, inf, 1e300, 1e308]])
    for n_f, n_g in ((4, 4), (2, 1), (1, 0)):
        for pf, pg in zip(p.tolist(), q.tolist(), strict=True):  # Python floats: overflow to inf without a warning
            share = mis_weight_share(n_f, pf, n_g, pg, beta)
            over = mis_weight_over(n_f, pf, n_g, pg, beta)
            assert np.isfinite(share) and np.isfinite(over), (n_f, pf, n_g, pg)
            a, b = n_f * pf, n_g * pg
            if beta == 1.0 and 0 < a < inf and 0 <= b < inf and a + b < inf:
                total = Fraction(a) + Fraction(b)
                assert share == pytest.approx(float(Fraction(pf) / total), rel=1e-12, abs=1e-300)
                assert over == pytest.approx(float(1 / total), rel=1e-12, abs=1e-300)
            else:
                w = mis_weight(n_f, pf, n_g, pg, beta)
                assert share == w / n_f, (n_f, pf, n_g, pg)
                assert over == (w / a if 0 < a < inf else 0.0), (n_f, pf, n_g, pg)
