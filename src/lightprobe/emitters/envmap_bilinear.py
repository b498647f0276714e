"""The environment map's bilinear sampling density (``pdf="bilinear"``): the density *is* the map's own bilinear
luminance, weighted by sin(theta) at the nodes, as Mitsuba 3's ``envmap`` does with its bilinear 2D warp.

Why: the radiance is looked up bilinearly (Mitsuba's placement), so a sun of two texels is spread over a 3 x 3
footprint whose brightness varies linearly inside every texel.  A piecewise-constant PDF cannot follow that, and
the ratio L / p -- the light estimator's value -- swings across each cell; finer grids only shrink the swing
(peer scene, 64 spp, relMSE: 2x grid 0.000647, 4x 0.000615, 8x 0.000586, each finer grid slower).  A density that
is bilinear on the lookup's own nodes makes L / p nearly constant over the sun with the map's own resolution.

The nodes are the lookup's texel positions.  Columns: node i is column i mod W at u = (i + 0.5) / W, i = 0 .. W
(node W repeats column 0: the lookup is periodic), so the density lives on u' = u - 0.5 / W (wrapped), node i at
u' = i / W.  Rows: node j is row min(j, H - 1) at v = j / (NY - 1), NY = max(H, 2) (corner-aligned; a one-row map
gets two equal node rows).  Node weight = max(luminance - offset, 0) x s_j, where offset is 0 for the plain density
and the map's mean for MIS compensation (Karlik et al. 2019), and s_j is the mean of sin(pi v) under node j's hat
function: about sin(theta_j) inside, positive at the poles so that a two-row map keeps a density.

Density over the unit square (u', v): p(u', v) = bilinear(weights)(u', v) / integral; per steradian
p / (2 pi^2 sin theta) (the lat-long Jacobian, as pbrt's).

Sampling inverts the marginal in v, then the conditional in u' at that v, each exactly: the conditional CDF at v
is (1 - t) C_k + t C_(k+1) of the two rows' running trapezoid sums C (searched by bisection, both rows read at
each step), and inside an interval where the density goes linearly from a to b, the fraction m of its mass is
reached at t = 2 m / (a + sqrt(a^2 + 2 (b - a) m)) (the root of a t + (b - a) t^2 / 2 = m without cancellation).
The map from (u0, u1) to (u', v) is monotonic in each coordinate, so quasi-random points stay stratified.

Tables: the running sums, (NY, W + 1) float64 per density (plain and compensated); node weights are read from the
float32 luminance the map keeps anyway.  At the peer scene's 1024 x 512 map that is 8.4 MB for both, against
33.6 MB of CDFs for the 2x piecewise-constant grid.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_inline
from ..sampling.distributions import ONE_MINUS_EPSILON, find_interval

__all__ = ["BilinearDensity", "build_bilinear"]


#: equal-probability buckets of the guide tables (decisions.md 45): a bucket of the peer map's 1024 columns holds 4
#: of them on average, so a search takes about 2 steps instead of 10 (64 buckets saved less, 1024 no more; 257
#: int32 per node row: 0.5 MB per density for the peer map, 4 MB for an 8192 x 4096 one)
GUIDE_BUCKETS = 256


class BilinearDensity:
    """The running sums of one bilinear density (plain or compensated) and what its kernels need besides."""

    def __init__(self, row_sums: np.ndarray, marginal: np.ndarray, offset: float):
        self.row_sums = row_sums  # (NY, W + 1): per node row, running trapezoid sums of the node weights
        self.marginal = marginal  # (NY,): running sums of the row intervals' masses
        self.offset = offset  # subtracted from the luminance before weighting (0: plain)
        # guide (cutpoint) tables for the searches of :func:`bilinear_sample`: entry g is the largest index whose
        # running sum is at most g / G of the total (-1 throughout for a row of weight 0); only a hint, which the
        # sampling lanes check before they use it (emitters/envmap_lanes.py)
        self.marginal_guide = np.empty(GUIDE_BUCKETS + 1, np.int32)
        _guide(marginal[None, :], self.marginal_guide[None, :])
        self.row_guide = np.empty((row_sums.shape[0], GUIDE_BUCKETS + 1), np.int32)
        _guide(row_sums, self.row_guide)

    @property
    def total(self) -> float:
        return float(self.marginal[-1])


def node_sines(rows: int) -> np.ndarray:
    """s_j, j < NY = max(rows, 2): the mean of sin(pi v) under node j's hat function (8-point Gauss-Legendre on
    each side of the node; exact to ~1e-15 for these smooth integrands)."""
    ny = max(rows, 2)
    h = 1.0 / (ny - 1)
    x, w = np.polynomial.legendre.leggauss(8)
    t = 0.5 * (x + 1.0)  # [0, 1]
    s = np.zeros(ny)
    mass = np.zeros(ny)
    nodes = np.arange(ny) * h
    for side in (-1.0, 1.0):
        v = nodes[:, None] + side * h * t[None, :]
        hat = 1.0 - t[None, :]
        inside = (v >= 0.0) & (v <= 1.0)
        weight = 0.5 * h * w[None, :] * hat * inside
        s += (weight * np.sin(np.pi * np.clip(v, 0.0, 1.0))).sum(axis=1)
        mass += weight.sum(axis=1)
    return s / mass


@jit
def node_weight(lum, sines, offset, j, i):
    """Weight of node (j, i): row min(j, H - 1), column i wrapped (i <= W)."""
    jj = min(j, lum.shape[0] - 1)  # a one-row map: both node rows are row 0
    ii = i if i < lum.shape[1] else i - lum.shape[1]
    x = lum[jj, ii] - offset
    return x * sines[j] if x > 0.0 else 0.0


@jit  # serial, as _guide: a parallel loop's compile costs a first render more than it saves (decisions.md 121)
def _row_sums(lum, sines, offset, out):
    ny, n1 = out.shape
    for j in range(ny):
        prev = node_weight(lum, sines, offset, j, 0)
        run = 0.0
        out[j, 0] = 0.0
        for i in range(n1 - 1):
            nxt = node_weight(lum, sines, offset, j, i + 1)
            run += 0.5 * (prev + nxt)
            out[j, i + 1] = run
            prev = nxt


@jit
def _guide(sums, out):
    """out[j, g] = the largest i < n - 1 with sums[j, i] <= g / G sums[j, n - 1] (G = out.shape[1] - 1), for each
    row of running sums (j, n); -1 for a row whose total is not positive."""
    rows, n = sums.shape
    buckets = out.shape[1] - 1
    for j in range(rows):
        total = sums[j, n - 1]
        if not total > 0.0:
            for g in range(buckets + 1):
                out[j, g] = -1
            continue
        i = 0
        for g in range(buckets + 1):
            threshold = g / buckets * total
            while i + 1 < n - 1 and sums[j, i + 1] <= threshold:
                i += 1
            out[j, g] = i


def _density(lum: np.ndarray, sines: np.ndarray, offset: float, fresh) -> BilinearDensity:
    ny = sines.shape[0]
    row_sums = fresh((ny, lum.shape[1] + 1), np.float64)
    _row_sums(lum, sines, offset, row_sums)
    ends = row_sums[:, -1]
    marginal = np.zeros(ny)
    marginal[1:] = np.cumsum(0.5 * (ends[:-1] + ends[1:]))
    return BilinearDensity(row_sums, marginal, offset)


def build_bilinear(lum: np.ndarray, mean: float, fresh) -> tuple[np.ndarray, BilinearDensity, BilinearDensity]:
    """(node sines, plain density, compensated density) of a float32 luminance (H, W) whose solid-angle mean is
    ``mean``; ``fresh(shape, dtype)`` allocates the tables.  A map with nothing above its mean (a constant map) gets
    the plain density twice."""
    sines = node_sines(lum.shape[0])
    plain = _density(lum, sines, 0.0, fresh)
    compensated = _density(lum, sines, mean, fresh)
    if not compensated.total > 0.0:
        compensated = plain
    return sines, plain, compensated


# --- kernels: coordinates (x, y) = (u', v) in the unit square ---------------------------------------------------
@jit_inline
def _invert_linear(a, b, m):
    """t in [0, 1] with a t + (b - a) t^2 / 2 = m: where a density going linearly from a to b has mass m."""
    den = a + math.sqrt(max(a * a + 2.0 * (b - a) * m, 0.0))
    if den <= 0.0:
        return 0.0
    return min(max(2.0 * m / den, 0.0), 1.0)


@jit_inline
def _column_pair(lum, sines, offset, k, t, i):
    """Weights of node columns i and i + 1 at the fraction t between node rows k and k + 1."""
    s = 1.0 - t
    c0 = s * node_weight(lum, sines, offset, k, i) + t * node_weight(lum, sines, offset, k + 1, i)
    c1 = s * node_weight(lum, sines, offset, k, i + 1) + t * node_weight(lum, sines, offset, k + 1, i + 1)
    return c0, c1


@jit_inline
def bilinear_sample(lum, sines, offset, row_sums, marginal, u0, u1):
    """(x, y, density over the unit square, column, tx, row, t) of the sample that (u0, u1) maps to: x = (column +
    tx) / W and y = (row + t) / (NY - 1), the cell and the fractions inside it (for :func:`sample_angles`)."""
    ny, n1 = row_sums.shape
    w = n1 - 1
    total = marginal[ny - 1]
    target = min(max(u1, 0.0), ONE_MINUS_EPSILON) * total
    k = find_interval(marginal, target)
    a = row_sums[k, w]
    b = row_sums[k + 1, w]
    t = _invert_linear(a, b, target - marginal[k])
    s = 1.0 - t
    target_x = min(max(u0, 0.0), ONE_MINUS_EPSILON) * (s * a + t * b)
    lo = 0
    hi = w
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if s * row_sums[k, mid] + t * row_sums[k + 1, mid] <= target_x:
            lo = mid
        else:
            hi = mid
    c0, c1 = _column_pair(lum, sines, offset, k, t, lo)
    tx = _invert_linear(c0, c1, target_x - (s * row_sums[k, lo] + t * row_sums[k + 1, lo]))
    x = (lo + tx) / w
    if x >= 1.0:
        x = ONE_MINUS_EPSILON
    y = min((k + t) / (ny - 1), 1.0)
    return x, y, ((1.0 - tx) * c0 + tx * c1) * (w * (ny - 1)) / total, lo, tx, k, t


# --- a sample's angles without libm -------------------------------------------------------------------------------
# cos(theta), sin(phi) and cos(phi) of a sample cost three libm calls, about 40 of the 157 core-ns of an environment
# sample on the peer scene (decisions.md 33).  Every sample lies in a known cell, so each angle is a node's angle,
# read from a table, plus a small one: theta = pi (row + t) / (NY - 1), phi = 2 pi (column + 0.5 + tx) / W, and
# cos(a + d) = cos a cos d - sin a sin d, sin(a + d) = sin a cos d + cos a sin d with d at most 0.05 rad, where the
# Taylor polynomials below are exact to about 1e-22 (truncation) -- rounding (a few units in the last place)
# is all that separates them from libm.  Maps too small for |d| <= 0.05 keep libm.
SMALL_ANGLE_ROWS = 64  # node rows from which pi / (NY - 1) <= 0.05
SMALL_ANGLE_COLUMNS = 128  # columns from which 2 pi / W <= 0.05


def angle_tables(ny: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) of the node rows' theta = pi j / (NY - 1), (NY, 2), and of the columns' phi = 2 pi (i + 0.5) / W,
    (W, 2)."""
    theta = np.pi * np.arange(ny) / (ny - 1)
    phi = 2.0 * np.pi * (np.arange(w) + 0.5) / w
    return np.stack([np.cos(theta), np.sin(theta)], 1), np.stack([np.cos(phi), np.sin(phi)], 1)


@jit_inline
def _small_cos_sin(d):
    """(cos d, sin d) for |d| <= 0.05 by Taylor polynomials (truncation below 1e-21)."""
    d2 = d * d
    c = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0 - d2 * (1.0 / 720.0 - d2 * (1.0 / 40320.0 - d2 / 3628800.0))))
    s = d * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 * (1.0 / 5040.0 - d2 / 362880.0))))
    return c, s


@jit_inline
def sample_angles(row_angles, column_angles, row, t, column, tx):
    """(cos theta, sin phi, cos phi) of a sample in node row ``row`` at fraction ``t`` and column ``column`` at
    fraction ``tx`` (the tables of :func:`angle_tables`; see the comment above)."""
    ny = row_angles.shape[0]
    w = column_angles.shape[0]
    cd, sd = _small_cos_sin(math.pi * t / (ny - 1))
    cos_theta = row_angles[row, 0] * cd - row_angles[row, 1] * sd
    cd, sd = _small_cos_sin(2.0 * math.pi * tx / w)
    ca, sa = column_angles[column, 0], column_angles[column, 1]
    return cos_theta, sa * cd + ca * sd, ca * cd - sa * sd


@jit_inline
def _cell(n, x):
    """Interval index and offset of x in [0, 1] on n intervals."""
    f = min(max(x, 0.0), 1.0) * n
    i = min(int(f), n - 1)
    return i, f - i


@jit_inline
def bilinear_pdf(lum, sines, offset, marginal, x, y):
    """Density over the unit square at (x, y)."""
    ny = marginal.shape[0]
    w = lum.shape[1]
    if not (x >= 0.0 and x <= 1.0 and y >= 0.0 and y <= 1.0):  # also rejects NaN
        return 0.0
    k, t = _cell(ny - 1, y)
    i, tx = _cell(w, x)
    c0, c1 = _column_pair(lum, sines, offset, k, t, i)
    return ((1.0 - tx) * c0 + tx * c1) * (w * (ny - 1)) / marginal[ny - 1]


@jit_inline
def bilinear_invert(lum, sines, offset, row_sums, marginal, x, y):
    """The (u0, u1) that :func:`bilinear_sample` maps to (x, y)."""
    ny, n1 = row_sums.shape
    w = n1 - 1
    k, t = _cell(ny - 1, y)
    a = row_sums[k, w]
    b = row_sums[k + 1, w]
    u1 = (marginal[k] + a * t + 0.5 * (b - a) * t * t) / marginal[ny - 1]
    i, tx = _cell(w, x)
    s = 1.0 - t
    c0, c1 = _column_pair(lum, sines, offset, k, t, i)
    row_total = s * a + t * b
    base = s * row_sums[k, i] + t * row_sums[k + 1, i]
    u0 = (base + c0 * tx + 0.5 * (c1 - c0) * tx * tx) / row_total if row_total > 0.0 else x
    return u0, u1
