"""The environment map's sampling distributions, built in two parallel passes over the PDF grid.

An 8192 x 4096 map has 33.5 M texels; building its distributions with whole-array NumPy expressions took 39 s and
a 10 GB peak (float64 temporaries of every intermediate, the 4 x 4-point bilinear quadrature evaluated point by
point, a refined copy of each array).  Here:

* the bilinear cell mean is computed *separably*: the bilinear reconstruction is a tensor product of a hat
  function in u and one in v, so its mean over a cell from k x k quadrature points is (mean of the k u-weights)
  x (mean of the k v-weights) -- at most 3 texels per axis, precomputed once per column and per row;
* pass 1 writes the cell weights (float32) and their per-row sums; the solid-angle mean that MIS compensation
  subtracts follows from the sums;
* pass 2 turns every row into its plain and compensated conditional CDFs (float64) in one sweep.

Extra memory: the float32 luminance and cell weights plus the two float64 CDF tables.  Measured in decisions.md
(entry 22).
"""

from __future__ import annotations

import math

import numpy as np

from .._memory import fresh_array
from .._numba import jit, jit_parallel, prange
from ..color import LUMINANCE_WEIGHTS
from ..sampling.distributions import PiecewiseConstant2D
from .mappings import bilinear_latlong_weights

__all__ = ["WEIGHT_MODES", "build_distributions", "luminance_f32"]

#: how a PDF cell's weight is computed from the luminance (see the ``pdf_weights`` option of EnvironmentMap)
WEIGHT_MODES = {"bilinear": 0, "texel": 1, "blur": 2}
_SUPPORT_BLUR = 1e-4  # share of pbrt's blurred luminance added to bilinear weights: no lit direction gets pdf 0


@jit  # serial: a parallel loop's compile costs a new user's first render more than it saves (decisions.md 121)
def _luminance(image, weights, out):
    for j in range(image.shape[0]):
        for i in range(image.shape[1]):
            out[j, i] = weights[0] * image[j, i, 0] + weights[1] * image[j, i, 1] + weights[2] * image[j, i, 2]


def luminance_f32(image: np.ndarray) -> np.ndarray:
    """Luminance (H, W) float32 of a float32 RGB image, without float64 temporaries."""
    out = fresh_array(image.shape[:2], np.float32)
    _luminance(image, LUMINANCE_WEIGHTS, out)
    return out


def _hat_taps(cells: int, texels: int, k: int, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``cells`` equal cells along an axis, the texels and weights of the mean of the bilinear hat
    functions at k evenly spaced points (Mitsuba's placement: u texel centres at (i + 0.5)/W, periodic; v rows at
    j/(H - 1), clamped).  Returns (index, weight), each (cells, taps)."""
    index = np.zeros((cells, 2 * k), np.int64)
    weight = np.zeros((cells, 2 * k))
    _fill_hat_taps(cells, texels, k, axis == "u", index, weight)
    used = max(1, int((weight != 0.0).sum(axis=1).max()))
    return np.ascontiguousarray(index[:, :used]), np.ascontiguousarray(weight[:, :used])


@jit
def _fill_hat_taps(cells, texels, k, periodic, index, weight):
    for c in range(cells):
        n = 0
        for a in range(k):
            pos = (c + (a + 0.5) / k) / cells
            # the lookup's own weights along one axis (the other axis a single texel)
            if periodic:
                _, _, lo, hi, _, t = bilinear_latlong_weights(1, texels, pos, 0.0)
            else:
                lo, hi, _, _, t, _ = bilinear_latlong_weights(texels, 1, 0.5, pos)
            for texel, wt in ((lo, (1.0 - t) / k), (hi, t / k)):
                found = False
                for m in range(n):  # merge taps on the same texel
                    if index[c, m] == texel:
                        weight[c, m] += wt
                        found = True
                        break
                if not found:
                    index[c, n] = texel
                    weight[c, n] = wt
                    n += 1


@jit_parallel
def _cell_weights(lum, f, mode, vi, vw, ui, uw, blur_share, solid_angle, out, row_sums):
    """Pass 1: each cell's weight (``mode`` of WEIGHT_MODES) and each row's sum weighted by the cell solid angle."""
    h, w = lum.shape
    for r in prange(out.shape[0]):
        j = r // f
        mix = np.zeros(w)
        if mode == 0:
            for t in range(vi.shape[1]):
                a = vw[r, t]
                if a != 0.0:
                    for x in range(w):
                        mix[x] += a * lum[vi[r, t], x]
        blur = np.zeros(w)
        if mode != 1:
            up, down = max(j - 1, 0), min(j + 1, h - 1)
            for x in range(w):
                blur[x] = 0.25 * lum[up, x] + 0.5 * lum[j, x] + 0.25 * lum[down, x]
        total = 0.0
        for c in range(out.shape[1]):
            i = c // f
            if mode == 1:
                value = float(lum[j, i])
            else:
                left = i - 1 if i > 0 else w - 1
                right = i + 1 if i < w - 1 else 0
                b = 0.25 * blur[left] + 0.5 * blur[i] + 0.25 * blur[right]
                if mode == 2:
                    value = b
                else:
                    value = blur_share * b
                    for t in range(ui.shape[1]):
                        value += uw[c, t] * mix[ui[c, t]]
            out[r, c] = value
            total += value
        row_sums[r] = total * solid_angle[r]


@jit_parallel
def _conditional_cdfs(weights, row_factor, mean, cdf, comp_cdf, integral, comp_integral):
    """Pass 2: per row, the CDF of weight x row_factor and of max(weight - mean, 0) x row_factor, normalised by
    their own totals (all-zero rows become uniform), and the rows' means.  The row's totals come first (the row
    is then in cache), so each CDF entry is written once, as running sum / total: non-decreasing, exactly 1 at the
    end."""
    n = weights.shape[1]
    for r in prange(weights.shape[0]):
        s = 0.0
        sc = 0.0
        for c in range(n):
            v = float(weights[r, c])
            s += v * row_factor[r]
            sc += max(v - mean, 0.0) * row_factor[r]
        integral[r] = s / n
        comp_integral[r] = sc / n
        cdf[r, 0] = 0.0
        comp_cdf[r, 0] = 0.0
        run = 0.0
        run_c = 0.0
        for c in range(n):
            v = float(weights[r, c])
            run += v * row_factor[r]
            run_c += max(v - mean, 0.0) * row_factor[r]
            cdf[r, c + 1] = run / s if s > 0.0 else (c + 1) / n
            comp_cdf[r, c + 1] = run_c / sc if sc > 0.0 else (c + 1) / n


def build_distributions(
    lum: np.ndarray, f: int, mode: str, row_factor: np.ndarray, cell_solid_angle: np.ndarray
) -> tuple[PiecewiseConstant2D, PiecewiseConstant2D]:
    """The plain and the MIS-compensated distributions on a grid ``f`` times finer than ``lum`` (H, W).

    ``row_factor`` (H f,) turns a cell weight into its probability weight (the row's solid angle for the exact PDF,
    sin theta for pbrt's); ``cell_solid_angle`` (H f,) is one cell's solid angle per row, for the compensation's
    mean.  A map with nothing above its mean (a constant map) gets the plain distribution twice.
    """
    h, w = lum.shape
    rows, cols = h * f, w * f
    k = max(1, 4 // f)
    vi, vw = _hat_taps(rows, h, k, "v")
    ui, uw = _hat_taps(cols, w, k, "u")
    weights = fresh_array((rows, cols), np.float32)
    row_sums = np.empty(rows)
    _cell_weights(lum, f, WEIGHT_MODES[mode], vi, vw, ui, uw, _SUPPORT_BLUR, cell_solid_angle, weights, row_sums)
    mean = float(row_sums.sum()) / (4.0 * math.pi)
    cdf = fresh_array((rows, cols + 1), np.float64)
    comp_cdf = fresh_array((rows, cols + 1), np.float64)
    integral = np.empty(rows)
    comp_integral = np.empty(rows)
    _conditional_cdfs(
        weights, np.ascontiguousarray(row_factor, np.float64), mean, cdf, comp_cdf, integral, comp_integral
    )
    del weights
    plain = PiecewiseConstant2D.from_cdfs(cdf, integral)
    if not comp_integral.max() > 0.0:  # nothing above the mean: compensation would leave no distribution
        return plain, plain
    return plain, PiecewiseConstant2D.from_cdfs(comp_cdf, comp_integral)
