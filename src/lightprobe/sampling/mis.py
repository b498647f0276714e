"""Multiple importance sampling heuristics (Veach & Guibas 1995; Krivanek eq. 17).

For a sample drawn from technique *f* (``n_f`` samples, density ``p_f``) that technique *g* (``n_g`` samples,
density ``p_g``) could also have produced::

    balance:  w_f = n_f p_f / (n_f p_f + n_g p_g)
    power:    w_f = (n_f p_f)^beta / ((n_f p_f)^beta + (n_g p_g)^beta),   beta = 2 by default

Both are computed from the ratio r = (n_g p_g) / (n_f p_f) as 1 / (1 + r^beta), which cannot overflow.  Safe for
degenerate densities: ``p_f = 0`` or NaN gives weight 0 (such a sample contributes nothing), an infinite ``p_f``
against a finite ``p_g`` gives 1 (a delta technique takes the whole weight), two infinite densities give 0, and a
technique with ``n = 0`` samples gets weight 0 while the other gets 1.  Weights of f and g always sum to 1
wherever at least one density is positive and finite.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_parallel, prange

__all__ = ["balance_heuristic", "mis_weight", "mis_weight_over", "mis_weight_share", "power_heuristic"]


@jit
def mis_weight(n_f, p_f, n_g, p_g, beta):
    """Weight of a sample from technique f against technique g (``beta = 1``: balance, 2: power)."""
    a = n_f * p_f
    b = n_g * p_g
    if not a > 0.0:  # zero, negative or NaN
        return 0.0
    if not b > 0.0:  # the other technique cannot produce this sample (NaN counts as "cannot")
        return 1.0 if a == a else 0.0
    if math.isinf(a):
        return 0.0 if math.isinf(b) else 1.0
    if math.isinf(b):
        return 0.0
    r = b / a
    if beta == 1.0:
        return 1.0 / (1.0 + r)
    if beta == 2.0:
        return 1.0 / (1.0 + r * r)
    return 1.0 / (1.0 + r**beta)


@jit
def _balance_total(n_f, p_f, n_g, p_g, beta):
    """n_f p_f + n_g p_g where the one-division forms below apply (the balance heuristic, n_f p_f > 0, n_g p_g >= 0,
    the sum finite), 0 elsewhere (they then go through mis_weight)."""
    a = n_f * p_f
    b = n_g * p_g
    if beta == 1.0 and a > 0.0 and b >= 0.0 and a + b < math.inf:
        return a + b
    return 0.0


@jit
def mis_weight_over(n_f, p_f, n_g, p_g, beta):
    """``mis_weight(n_f, p_f, n_g, p_g, beta) / (n_f p_f)``, the factor a sample's f / p_f takes: its contribution is
    f w_f / (n_f p_f). Under the balance heuristic that is 1 / (n_f p_f + n_g p_g), one division where the weight
    and the two divisions after it take four (decisions.md 63); the degenerate cases are mis_weight's (0 where
    n_f p_f is not a positive number)."""
    total = _balance_total(n_f, p_f, n_g, p_g, beta)
    if total > 0.0:
        return 1.0 / total
    a = n_f * p_f
    if not a > 0.0:
        return 0.0
    return mis_weight(n_f, p_f, n_g, p_g, beta) / a


@jit
def mis_weight_share(n_f, p_f, n_g, p_g, beta):
    """``mis_weight(n_f, p_f, n_g, p_g, beta) / n_f``, a sample's share when f takes n_f samples: p_f / (n_f p_f +
    n_g p_g) under the balance heuristic, one division for two."""
    total = _balance_total(n_f, p_f, n_g, p_g, beta)
    if total > 0.0:
        return p_f / total
    return mis_weight(n_f, p_f, n_g, p_g, beta) / n_f


@jit_parallel
def _weight_batch(n_f, p_f, n_g, p_g, beta):
    out = np.empty(p_f.shape[0])
    for i in prange(p_f.shape[0]):
        out[i] = mis_weight(n_f, p_f[i], n_g, p_g[i], beta)
    return out


def _weights(n_f, p_f, n_g, p_g, beta):
    if n_f < 0 or n_g < 0:
        raise ValueError(f"sample counts must be >= 0, got n_f={n_f}, n_g={n_g}")
    pf, pg = np.broadcast_arrays(np.asarray(p_f, dtype=np.float64), np.asarray(p_g, dtype=np.float64))
    shape = pf.shape
    out = _weight_batch(
        float(n_f),
        np.ascontiguousarray(pf.reshape(-1)),
        float(n_g),
        np.ascontiguousarray(pg.reshape(-1)),
        beta,
    )
    return out.reshape(shape) if shape else float(out[0])


def balance_heuristic(p_f, p_g, *, n_f: float = 1, n_g: float = 1):
    """Balance-heuristic weight of samples from f (densities ``p_f``) against g (densities ``p_g``)."""
    return _weights(n_f, p_f, n_g, p_g, 1.0)


def power_heuristic(p_f, p_g, *, n_f: float = 1, n_g: float = 1, beta: float = 2.0):
    """Power-heuristic weight (exponent ``beta``, Veach's choice 2) of samples from f against g."""
    if not beta > 0.0:
        raise ValueError(f"beta must be > 0, got {beta}")
    return _weights(n_f, p_f, n_g, p_g, float(beta))
