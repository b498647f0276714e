"""Piecewise-constant distributions in 1D and 2D (Krivanek sec. 3.1 and 3.4; pbrt's ``PiecewiseConstant1D/2D``).

A 1D distribution over [0, 1) is given by ``n`` non-negative bin values.  Sampling picks a bin with probability
proportional to its value (inverting the CDF by bisection) and then places the sample *continuously* inside the bin,
using the remainder of ``u`` as the offset.  That makes the map from ``u`` to ``x`` monotonic and invertible, so
stratified and quasi-random ``u`` stay stratified, and the density is exactly the normalised bin value.  Only the
CDFs are stored: a bin's density is n (cdf[i+1] - cdf[i]), the probability the sampler actually gives it.

The 2D distribution over [0, 1)^2 is a marginal over rows (``y``) and one conditional per row (``x``), the seed's
construction: ``p(x, y) = p_rows(y) * p(x | row)``.

Degenerate input is handled deliberately, never by dividing by zero:

* an all-zero row of a 2D function gets probability 0 in the marginal; its conditional is defined as uniform so
  that the structure stays well formed (it is never sampled, and its joint density is 0 anyway);
* an all-zero function (1D or 2D) becomes the *uniform* distribution (density 1 everywhere) and ``integral`` is 0,
  so callers can detect it; sampling and ``pdf`` stay consistent with each other;
* negative, NaN or infinite values are rejected with ``ValueError``.

Densities are with respect to the unit interval / unit square (multiply ``x`` by the domain size yourself, or use
``domain=`` in 1D).
"""

from __future__ import annotations

import numpy as np

from .._numba import jit, jit_inline
from .._worksharing import in_threads

__all__ = ["PiecewiseConstant1D", "PiecewiseConstant2D"]

ONE_MINUS_EPSILON = 1.0 - 2.0**-53


def _normalized_cdf(func: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CDFs along the last axis (all-zero rows become uniform) and the integrals (means) of the rows."""
    n = func.shape[-1]
    integral = func.mean(axis=-1)
    zero = integral <= 0.0
    values = np.where(zero[..., None], 1.0, func)
    sums = np.cumsum(values, axis=-1)
    cdf = np.zeros((*func.shape[:-1], n + 1))
    # dividing the running sums by their own total keeps the CDF non-decreasing, <= 1, and exactly 1 at the end
    # (so u < 1 never selects a trailing empty bin and no bin gets a negative width)
    cdf[..., 1:] = sums / sums[..., -1:]
    return cdf, integral


def _check_function(func, ndim: int, name: str) -> np.ndarray:
    arr = np.asarray(func, dtype=np.float64)
    if arr.ndim != ndim or min(arr.shape) < 1:
        raise ValueError(f"{name} must be a non-empty {ndim}D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    if np.any(arr < 0.0):
        raise ValueError(f"{name} contains negative values (min {arr.min():g})")
    return np.ascontiguousarray(arr)


# --- a choice between two options, from a coordinate the sample also uses --------------------------------------
@jit_inline
def choose_rescaled(u, p):
    """The first of two options with probability ``p`` (``u < p``), and ``u`` rescaled to [0, 1) within the
    chosen option's share of [0, 1): (first chosen, u').  pbrt-v3's remapping of a BSDF's lobe choice
    (``BSDF::Sample_f``): given u uniform, u' is uniform whichever option is chosen, so a two-lobe BSDF can choose
    its lobe with one coordinate of its 2D pair and still sample the lobe with both.  From a stratified set (a
    Sobol' (0, m, 2)-net) each lobe then gets a stratum of it -- the points with u < p, stretched -- where a choice
    by a number of its own would give each lobe a scattered subset (peer scene: 7 % lower relMSE, decisions.md 67).
    """
    if u < p:
        return True, min(u / p, ONE_MINUS_EPSILON)
    return False, min((u - p) / (1.0 - p), ONE_MINUS_EPSILON)


# --- scalar kernels (used by the environment map) ---------------------------------------------------------------
# The density of bin i is n (cdf[i+1] - cdf[i]): exactly the probability the sampler gives the bin, and no second
# array to read (the search has already loaded cdf[i] and cdf[i+1]).
@jit
def find_interval(cdf, u):
    """Largest i in [0, len(cdf) - 2] with cdf[i] <= u (bisection)."""
    lo = 0
    hi = cdf.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if cdf[mid] <= u:
            lo = mid
        else:
            hi = mid
    return lo


@jit
def sample_1d(cdf, u):
    """Sample x in [0, 1) from a row: returns (x, density at x, bin index)."""
    n = cdf.shape[0] - 1
    u = min(max(u, 0.0), ONE_MINUS_EPSILON)
    i = find_interval(cdf, u)
    width = cdf[i + 1] - cdf[i]
    offset = (u - cdf[i]) / width if width > 0.0 else 0.0
    x = (i + offset) / n
    if x >= 1.0:  # rounding at the top of the last bin
        x = ONE_MINUS_EPSILON
    return x, width * n, i


@jit
def pdf_1d(cdf, x):
    n = cdf.shape[0] - 1
    if not (x >= 0.0 and x <= 1.0):  # also rejects NaN
        return 0.0
    i = min(int(x * n), n - 1)
    return (cdf[i + 1] - cdf[i]) * n


@jit
def invert_1d(cdf, x):
    n = cdf.shape[0] - 1
    t = min(max(x, 0.0), 1.0) * n
    i = min(int(t), n - 1)
    return cdf[i] + (t - i) * (cdf[i + 1] - cdf[i])


@jit
def sample_2d(marginal_cdf, conditional_cdf, u0, u1):
    """Sample (x, y) in [0, 1)^2: the row from the marginal with u1, the column from that row with u0.

    Returns (x, y, joint density, column index, row index).
    """
    y, p_row, row = sample_1d(marginal_cdf, u1)
    x, p_col, col = sample_1d(conditional_cdf[row], u0)
    return x, y, p_row * p_col, col, row


@jit
def pdf_2d(marginal_cdf, conditional_cdf, x, y):
    ny = marginal_cdf.shape[0] - 1
    if not (y >= 0.0 and y <= 1.0):
        return 0.0
    row = min(int(y * ny), ny - 1)
    return (marginal_cdf[row + 1] - marginal_cdf[row]) * ny * pdf_1d(conditional_cdf[row], x)


@jit
def invert_2d(marginal_cdf, conditional_cdf, x, y):
    ny = marginal_cdf.shape[0] - 1
    row = min(int(min(max(y, 0.0), 1.0) * ny), ny - 1)
    return invert_1d(conditional_cdf[row], x), invert_1d(marginal_cdf, y)


# --- batch kernels ----------------------------------------------------------------------------------------------
# Range kernels run by threads (``_worksharing.in_threads``), not ``prange`` loops: the same values (each item is its
# own), and Numba's parallel-loop passes made them slow to compile (decisions.md 129, 131).
@jit
def _sample_1d_range(cdf, u, x, pdf, index, lo, hi):
    for i in range(lo, hi):
        x[i], pdf[i], index[i] = sample_1d(cdf, u[i])


def _sample_1d_batch(cdf, u):
    x = np.empty(u.shape[0])
    pdf = np.empty(u.shape[0])
    index = np.empty(u.shape[0], dtype=np.int64)
    in_threads(_sample_1d_range, u.shape[0], cdf, u, x, pdf, index)
    return x, pdf, index


@jit
def _pdf_1d_range(cdf, x, out, lo, hi):
    for i in range(lo, hi):
        out[i] = pdf_1d(cdf, x[i])


def _pdf_1d_batch(cdf, x):
    out = np.empty(x.shape[0])
    in_threads(_pdf_1d_range, x.shape[0], cdf, x, out)
    return out


@jit
def _invert_1d_range(cdf, x, out, lo, hi):
    for i in range(lo, hi):
        out[i] = invert_1d(cdf, x[i])


def _invert_1d_batch(cdf, x):
    out = np.empty(x.shape[0])
    in_threads(_invert_1d_range, x.shape[0], cdf, x, out)
    return out


@jit
def _sample_2d_range(mc, cc, u, pts, pdf, lo, hi):
    for i in range(lo, hi):
        x, y, p, _, _ = sample_2d(mc, cc, u[i, 0], u[i, 1])
        pts[i, 0] = x
        pts[i, 1] = y
        pdf[i] = p


def _sample_2d_batch(mc, cc, u):
    pts = np.empty((u.shape[0], 2))
    pdf = np.empty(u.shape[0])
    in_threads(_sample_2d_range, u.shape[0], mc, cc, u, pts, pdf)
    return pts, pdf


@jit
def _pdf_2d_range(mc, cc, pts, out, lo, hi):
    for i in range(lo, hi):
        out[i] = pdf_2d(mc, cc, pts[i, 0], pts[i, 1])


def _pdf_2d_batch(mc, cc, pts):
    out = np.empty(pts.shape[0])
    in_threads(_pdf_2d_range, pts.shape[0], mc, cc, pts, out)
    return out


@jit
def _invert_2d_range(mc, cc, pts, out, lo, hi):
    for i in range(lo, hi):
        out[i, 0], out[i, 1] = invert_2d(mc, cc, pts[i, 0], pts[i, 1])


def _invert_2d_batch(mc, cc, pts):
    out = np.empty((pts.shape[0], 2))
    in_threads(_invert_2d_range, pts.shape[0], mc, cc, pts, out)
    return out


def _column(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1))


def _pairs(a, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must be an (N, 2) array, got shape {arr.shape}")
    return np.ascontiguousarray(arr)


class PiecewiseConstant1D:
    """A piecewise-constant density over ``domain`` (default [0, 1)) with ``len(func)`` equal bins.

    Parameters
    ----------
    func : array_like, shape (n,)
        Non-negative bin values; they need not sum to one.
    domain : (float, float), optional
        Interval covered by the bins.

    Attributes
    ----------
    integral : float
        Integral of ``func`` over ``domain`` (0 for an all-zero function, which samples uniformly).
    """

    def __init__(self, func, *, domain: tuple[float, float] = (0.0, 1.0)):
        values = _check_function(func, 1, "func")
        lo, hi = float(domain[0]), float(domain[1])
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise ValueError(f"domain must be a finite interval (lo, hi) with hi > lo, got {domain}")
        self.func = values
        self.domain = (lo, hi)
        self.cdf, mean = _normalized_cdf(values)
        self.integral = float(mean) * (hi - lo)

    @property
    def size(self) -> int:
        return self.func.shape[0]

    @property
    def density(self) -> np.ndarray:
        """Density of each bin over [0, 1): n (cdf[i+1] - cdf[i])."""
        return np.diff(self.cdf) * self.size

    def sample(self, u):
        """Map ``u`` (N,) in [0, 1) to ``(x, pdf, bin_index)``; ``pdf`` is the density at ``x`` over ``domain``."""
        lo, hi = self.domain
        x, pdf, index = _sample_1d_batch(self.cdf, _column(u))
        return lo + (hi - lo) * x, pdf / (hi - lo), index

    def pdf(self, x):
        lo, hi = self.domain
        return _pdf_1d_batch(self.cdf, (_column(x) - lo) / (hi - lo)) / (hi - lo)

    def invert(self, x):
        """The ``u`` that ``sample`` maps to ``x`` (the CDF at ``x``)."""
        lo, hi = self.domain
        return _invert_1d_batch(self.cdf, (_column(x) - lo) / (hi - lo))


class PiecewiseConstant2D:
    """A piecewise-constant density over [0, 1)^2 from an ``(ny, nx)`` array (rows are ``y``, columns ``x``).

    ``sample(u)`` draws the row from the marginal with ``u[:, 1]`` and the column from that row's conditional
    with ``u[:, 0]``; points are ``(x, y)`` with continuous offsets inside the cell.

    Attributes
    ----------
    integral : float
        Integral of the function over the unit square (mean of ``func``); 0 means the uniform fallback.
    """

    def __init__(self, func):
        values = _check_function(func, 2, "func")
        self.conditional_cdf, row_means = _normalized_cdf(values)
        self.marginal_cdf, total = _normalized_cdf(row_means)
        self.integral = float(total)

    @classmethod
    def from_cdfs(cls, conditional_cdf: np.ndarray, row_means: np.ndarray) -> PiecewiseConstant2D:
        """From rows' normalised CDFs (ny, nx + 1) and the rows' means (ny,), as built by a caller that never holds
        the function itself in float64 (a large environment map)."""
        dist = cls.__new__(cls)
        dist.conditional_cdf = conditional_cdf
        dist.marginal_cdf, total = _normalized_cdf(np.asarray(row_means, np.float64))
        dist.integral = float(total)
        return dist

    @property
    def shape(self) -> tuple[int, int]:
        return self.conditional_cdf.shape[0], self.conditional_cdf.shape[1] - 1

    @property
    def marginal_density(self) -> np.ndarray:
        return np.diff(self.marginal_cdf) * (self.marginal_cdf.shape[0] - 1)

    @property
    def conditional_density(self) -> np.ndarray:
        return np.diff(self.conditional_cdf, axis=1) * (self.conditional_cdf.shape[1] - 1)

    def kernel_arrays(self):
        """(marginal_cdf, conditional_cdf) for the Numba kernels."""
        return self.marginal_cdf, self.conditional_cdf

    def sample(self, u):
        """Map ``u`` (N, 2) to ``(points (N, 2), pdf (N,))``."""
        return _sample_2d_batch(*self.kernel_arrays(), _pairs(u, "u"))

    def pdf(self, points):
        return _pdf_2d_batch(self.marginal_cdf, self.conditional_cdf, _pairs(points, "points"))

    def invert(self, points):
        return _invert_2d_batch(self.marginal_cdf, self.conditional_cdf, _pairs(points, "points"))
