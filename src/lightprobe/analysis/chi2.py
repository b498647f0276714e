"""Chi-square goodness-of-fit tests of a sampler against its own density, after Mitsuba 3's ``chi2.py``.

The domain is cut into cells; samples are counted per cell; the expected count of each cell is ``n`` times the
integral of the sampler's ``pdf()`` over the cell, computed by Gauss-Legendre quadrature.  Cells whose expected
count is below ``min_expected`` are pooled; the statistic is compared with the chi-square distribution and the
significance level is Sidak-corrected for the number of tests run (``test_count``).  The test also fails outright
when samples fall where the pdf integrates to zero, or when the pdf integrates to more than 1.

Spherical domains bin directions by polar angle ``theta`` about an axis and azimuth ``phi`` (a rotation ``frame``
whose rows are the local s, t, n axes).  Cell edges in theta can be anything: uniform, texel-aligned for an
environment map (:func:`texel_edges`, which makes the quadrature exact for a piecewise-constant pdf), or
equal-mass rings about a narrow lobe (:func:`equal_mass_theta_edges`, so that a lobe of 0.5 degrees is resolved by
many cells instead of falling into one).

Example
-------
>>> import numpy as np
>>> from lightprobe.analysis import chi2
>>> from lightprobe.sampling import warps
>>> u = np.random.default_rng(1).random((100_000, 2))
>>> result = chi2.spherical_test(warps.square_to_cosine_hemisphere(u), warps.cosine_hemisphere_pdf)
>>> result.passed
True
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._numba import jit

__all__ = [
    "ChiSquareResult",
    "check_bsdf_sampling",
    "check_envmap_sampling",
    "equal_mass_theta_edges",
    "goodness_of_fit",
    "spherical_counts",
    "spherical_expected",
    "spherical_test",
    "texel_edges",
]

PdfFunc = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class ChiSquareResult:
    """Outcome of a chi-square test; ``passed`` is False also for the outright failures described in ``message``."""

    statistic: float
    dof: int
    p_value: float
    alpha: float
    passed: bool
    message: str
    pdf_integral: float

    def __str__(self) -> str:
        verdict = "passed" if self.passed else "FAILED"
        return (
            f"chi2 {verdict}: statistic {self.statistic:.1f}, dof {self.dof}, p = {self.p_value:.3g} "
            f"(alpha {self.alpha:.2g}), pdf integral {self.pdf_integral:.6f}. {self.message}"
        )


def goodness_of_fit(
    observed: np.ndarray,
    expected: np.ndarray,
    *,
    alpha: float = 0.01,
    test_count: int = 1,
    min_expected: float = 5.0,
    integral_tolerance: float = 1e-3,
) -> ChiSquareResult:
    """Chi-square test of observed cell counts against expected counts (both any shape, same size).

    ``expected`` must be n times the pdf's integral over each cell, where n = ``observed.sum()``.
    """
    obs = np.asarray(observed, dtype=np.float64).reshape(-1)
    exp = np.asarray(expected, dtype=np.float64).reshape(-1)
    n = obs.sum()
    alpha_corrected = 1.0 - (1.0 - alpha) ** (1.0 / test_count)
    integral = exp.sum() / n if n > 0 else float("nan")

    def fail(message: str) -> ChiSquareResult:
        return ChiSquareResult(np.inf, 0, 0.0, alpha_corrected, False, message, integral)

    if n == 0:
        return fail("no samples")
    if not np.all(np.isfinite(exp)) or np.any(exp < 0):
        return fail("the pdf is negative, NaN or infinite somewhere")
    if integral > 1.0 + integral_tolerance:
        return fail(f"the pdf integrates to {integral:.6f} > 1")
    stray = obs[exp <= 0.0].sum()
    if stray > 0:
        return fail(f"{int(stray)} samples fell in cells where the pdf integrates to 0")

    # Pool cells with small expectations, smallest first, until each pool reaches min_expected (Mitsuba).
    big = exp >= min_expected
    pooled_obs, pooled_exp = list(obs[big]), list(exp[big])
    order = np.argsort(exp[~big], kind="stable")
    small_obs, small_exp = obs[~big][order], exp[~big][order]
    acc_o = acc_e = 0.0
    for o, e in zip(small_obs, small_exp, strict=True):
        acc_o += o
        acc_e += e
        if acc_e >= min_expected:
            pooled_obs.append(acc_o)
            pooled_exp.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0.0 or acc_o > 0.0:
        if pooled_exp:
            k = int(np.argmin(pooled_exp))
            pooled_obs[k] += acc_o
            pooled_exp[k] += acc_e
        else:
            pooled_obs.append(acc_o)
            pooled_exp.append(acc_e)
    po, pe = np.asarray(pooled_obs), np.asarray(pooled_exp)
    if po.size < 2:
        return ChiSquareResult(0.0, 0, 1.0, alpha_corrected, True, "a single cell holds everything", integral)
    statistic = float(np.sum((po - pe) ** 2 / pe))
    dof = po.size - 1
    from scipy import stats  # here, not at the top: 0.6 s of import for every process that only reads this module

    p_value = float(stats.chi2.sf(statistic, dof))
    passed = p_value > alpha_corrected
    message = f"{obs.size} cells pooled into {po.size}"
    if not passed:
        worst = np.argsort(-((po - pe) ** 2 / pe))[:3]
        message += "; worst cells (observed/expected): " + ", ".join(f"{po[i]:.0f}/{pe[i]:.1f}" for i in worst)
    return ChiSquareResult(statistic, dof, p_value, alpha_corrected, passed, message, integral)


# --- spherical domain ---------------------------------------------------------------------------------------------
def _frame(frame) -> np.ndarray:
    m = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    if m.shape != (3, 3) or not np.allclose(m @ m.T, np.eye(3), atol=1e-6):
        raise ValueError("frame must be a 3x3 orthonormal matrix whose rows are the local axes")
    return m


@jit
def _bin_of(edges, x):
    """The cell of ``x`` among ``edges`` (increasing): ``searchsorted(edges, x, side="right") - 1`` clipped to the
    cells 0 .. len(edges) - 2."""
    lo, hi = 0, edges.shape[0]  # the first edge above x lies in [lo, hi]
    while lo < hi:
        mid = (lo + hi) // 2
        if edges[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return min(max(lo - 1, 0), edges.shape[0] - 2)


@jit
def _count_directions(dirs, frame, theta_edges, phi_edges, counts):
    """Add each direction (turned into the frame: rows of ``frame`` are the local axes) to its (theta, phi) cell."""
    for i in range(dirs.shape[0]):
        x, y, z = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        lx = x * frame[0, 0] + y * frame[0, 1] + z * frame[0, 2]
        ly = x * frame[1, 0] + y * frame[1, 1] + z * frame[1, 2]
        lz = x * frame[2, 0] + y * frame[2, 1] + z * frame[2, 2]
        theta = math.acos(min(max(lz, -1.0), 1.0))
        phi = math.atan2(ly, lx) % (2.0 * math.pi)
        counts[_bin_of(theta_edges, theta), _bin_of(phi_edges, phi)] += 1.0


def spherical_counts(dirs, theta_edges, phi_edges, *, frame=None) -> np.ndarray:
    """Histogram of unit directions over (theta, phi) cells, shape (len(theta_edges)-1, len(phi_edges)-1).

    One compiled pass (the frame, the angles, a bisection per axis), 0.09-0.12 s for a million directions, where
    NumPy's matrix product, ``arctan2``, two ``searchsorted`` and ``add.at`` took 0.10-0.16 s with OpenBLAS on one
    thread and several times that with its threads spinning on a loaded machine (decisions.md 133)."""
    m = np.ascontiguousarray(_frame(frame))
    d = np.ascontiguousarray(dirs, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"dirs must be (N, 3), got {d.shape}")
    te = np.ascontiguousarray(theta_edges, dtype=np.float64)
    pe = np.ascontiguousarray(phi_edges, dtype=np.float64)
    counts = np.zeros((te.size - 1, pe.size - 1))
    _count_directions(d, m, te, pe, counts)
    return counts


@jit
def _quadrature_directions(t0, t1, p0, p1, s, phi_trig, frame, out):
    """The order x order Gauss nodes of each part [t0, t1] x [p0, p1] (``s`` the rule's nodes on [0, 1]), theta
    major, as unit vectors (sin t cos p, sin t sin p, cos t) turned into the frame: ``out`` (parts x order^2, 3).
    ``phi_trig`` (order, 2) is scratch for a part's sines and cosines of phi."""
    q = s.shape[0]
    for m in range(t0.shape[0]):
        for j in range(q):
            phi = p0[m] + (p1[m] - p0[m]) * s[j]
            phi_trig[j, 0] = math.sin(phi)
            phi_trig[j, 1] = math.cos(phi)
        for i in range(q):
            theta = t0[m] + (t1[m] - t0[m]) * s[i]
            st, ct = math.sin(theta), math.cos(theta)
            for j in range(q):
                x, y = st * phi_trig[j, 1], st * phi_trig[j, 0]
                row = (m * q + i) * q + j
                for k in range(3):
                    out[row, k] = x * frame[0, k] + y * frame[1, k] + ct * frame[2, k]


@jit
def _weighted_sums(values, t0, t1, p0, p1, s, w, out):
    """Each part's Gauss sum of ``values`` (its order^2 nodes' pdf, theta major) x sin(theta), times its area in
    (theta, phi)."""
    q = s.shape[0]
    for m in range(t0.shape[0]):
        dt, dp = t1[m] - t0[m], p1[m] - p0[m]
        total = 0.0
        for i in range(q):
            ring = 0.0
            for j in range(q):
                ring += values[(m * q + i) * q + j] * w[j]
            total += ring * w[i] * math.sin(t0[m] + dt * s[i])
        out[m] = total * dt * dp


def _cell_integrals(pdf: PdfFunc, t0, t1, p0, p1, frame: np.ndarray, order: int, chunk: int) -> np.ndarray:
    """Gauss-Legendre (order x order) integral of pdf(w) sin(theta) over each (theta, phi) rectangle.

    The nodes and the sums are compiled loops: in NumPy (every node's angles as arrays, then a product with the
    frame, then ``einsum``) a test that integrates 90 million nodes took 4.9 s, 2.0 s with these loops."""
    x, w = np.polynomial.legendre.leggauss(order)
    s = 0.5 * (x + 1.0)
    w = 0.5 * w
    frame = np.ascontiguousarray(frame, dtype=np.float64)
    t0, t1, p0, p1 = (np.ascontiguousarray(a, dtype=np.float64) for a in (t0, t1, p0, p1))
    phi_trig = np.empty((order, 2))
    out = np.empty(t0.size)
    per = max(1, chunk // (order * order))
    for a in range(0, t0.size, per):
        b = min(t0.size, a + per)
        dirs = np.empty(((b - a) * order * order, 3))
        _quadrature_directions(t0[a:b], t1[a:b], p0[a:b], p1[a:b], s, phi_trig, frame, dirs)
        values = np.ascontiguousarray(pdf(dirs), dtype=np.float64).reshape(-1)
        if values.size != dirs.shape[0]:
            raise ValueError(f"pdf returned {values.size} values for {dirs.shape[0]} directions")
        _weighted_sums(values, t0[a:b], t1[a:b], p0[a:b], p1[a:b], s, w, out[a:b])
    return out


def spherical_expected(
    pdf: PdfFunc,
    theta_edges,
    phi_edges,
    *,
    frame=None,
    subdivisions: int = 1,
    order: int = 4,
    rtol: float = 1e-5,
    atol: float = 1e-9,
    max_depth: int = 10,
    refine=None,
    refine_depth: int = 6,
    max_parts: int = 1 << 22,
    chunk: int = 1 << 20,
) -> np.ndarray:
    """Integral of ``pdf`` (per unit solid angle) over each (theta, phi) cell, by adaptive quadrature.

    Each cell is split into ``subdivisions`` x ``subdivisions`` equal parts, each integrated with an
    ``order`` x ``order`` Gauss-Legendre rule (with the sin(theta) Jacobian).  A part is then split in four and
    integrated again until the two estimates agree to ``max(atol, rtol * value)``, or ``max_depth`` levels: this
    resolves lobes far narrower than a cell and the edges of a pdf's support.  ``refine`` (a boolean array of the
    cells' shape) forces refinement of cells whose estimate is still 0 (use: cells that received samples) for up
    to ``refine_depth`` levels.  Refinement stops early if one level would integrate more than ``max_parts`` parts
    (the finest estimates are then used).
    """
    m = _frame(frame)
    te = np.asarray(theta_edges, dtype=np.float64)
    pe = np.asarray(phi_edges, dtype=np.float64)
    nt, npc = te.size - 1, pe.size - 1
    # initial parts: subdivisions^2 per cell
    frac = np.arange(subdivisions + 1) / subdivisions
    tb = te[:-1, None] + np.diff(te)[:, None] * frac[None, :]  # (nt, s+1)
    pb = pe[:-1, None] + np.diff(pe)[:, None] * frac[None, :]
    ti, pi_, si, sj = np.meshgrid(
        np.arange(nt), np.arange(npc), np.arange(subdivisions), np.arange(subdivisions), indexing="ij"
    )
    cell = (ti * npc + pi_).reshape(-1)
    t0, t1 = tb[ti, si].reshape(-1), tb[ti, si + 1].reshape(-1)
    p0, p1 = pb[pi_, sj].reshape(-1), pb[pi_, sj + 1].reshape(-1)
    force = np.zeros(nt * npc, dtype=bool) if refine is None else np.asarray(refine, dtype=bool).reshape(-1)

    result = np.zeros(nt * npc)
    coarse = _cell_integrals(pdf, t0, t1, p0, p1, m, order, chunk)
    for depth in range(max_depth):
        tm, pm = 0.5 * (t0 + t1), 0.5 * (p0 + p1)
        c_t0 = np.concatenate([t0, t0, tm, tm])
        c_t1 = np.concatenate([tm, tm, t1, t1])
        c_p0 = np.concatenate([p0, pm, p0, pm])
        c_p1 = np.concatenate([pm, p1, pm, p1])
        fine_parts = _cell_integrals(pdf, c_t0, c_t1, c_p0, c_p1, m, order, chunk)
        fine = fine_parts.reshape(4, -1).sum(axis=0)
        converged = np.abs(fine - coarse) <= np.maximum(atol, rtol * np.abs(fine))
        # a cell that received samples but has no mass yet: keep looking for the sliver of support
        found = result.copy()
        np.add.at(found, cell, fine)
        if depth < refine_depth:
            converged &= ~(force & (found == 0.0))[cell]
        np.add.at(result, cell[converged], fine[converged])
        keep = np.tile(~converged, 4)
        if not keep.any():
            break
        if int(keep.sum()) > max_parts:  # budget exhausted: accept the finest estimates
            np.add.at(result, cell[~converged], fine[~converged])
            break
        cell = np.tile(cell, 4)[keep]
        t0, t1, p0, p1 = c_t0[keep], c_t1[keep], c_p0[keep], c_p1[keep]
        coarse = fine_parts[keep]
    else:
        np.add.at(result, cell, coarse)
    return result.reshape(nt, npc)


def equal_mass_theta_edges(
    pdf: PdfFunc, n_rings: int, *, frame=None, n_uniform: int = 64, n_fine: int = 4096, n_phi: int = 64
) -> np.ndarray:
    """Theta edges of ``n_rings`` rings of (nearly) equal probability about the frame's axis.

    The mass is integrated on a fine grid theta = pi s^2 (dense near the axis, where narrow lobes live), so a
    lobe a fraction of a degree wide still spreads over many rings.  Edges are a subset of that fine grid, merged
    with ``n_uniform`` uniform rings so that no ring is wide (the tail of a lobe and the horizon stay resolved).
    """
    m = _frame(frame)
    fine = np.pi * np.linspace(0.0, 1.0, n_fine + 1) ** 2
    phi = np.linspace(0.0, 2.0 * np.pi, n_phi + 1)
    mass = spherical_expected(pdf, fine, phi, frame=m, order=2, max_depth=0).sum(axis=1)
    cdf = np.concatenate([[0.0], np.cumsum(mass)])
    if cdf[-1] <= 0:
        raise ValueError("the pdf integrates to zero")
    targets = np.linspace(0.0, cdf[-1], n_rings + 1)[1:-1]
    idx = np.unique(np.searchsorted(cdf, targets))
    return np.unique(np.concatenate([fine[idx], np.linspace(0.0, np.pi, n_uniform + 1)]))


def texel_edges(n_texels: int, n_cells: int, extent: float) -> np.ndarray:
    """Cell edges aligned with texel boundaries: ``n_cells`` cells over ``n_texels`` texels spanning ``extent``.

    With ``n_cells <= n_texels`` (and dividing it) each cell is a block of whole texels; with more cells than
    texels each texel is split evenly.  Either way a pdf that is constant per texel is integrated exactly.
    """
    if n_cells <= n_texels:
        if n_texels % n_cells:
            raise ValueError(f"{n_cells} cells do not divide {n_texels} texels")
    elif n_cells % n_texels:
        raise ValueError(f"{n_cells} cells are not a multiple of {n_texels} texels")
    return np.linspace(0.0, extent, n_cells + 1)


def spherical_test(
    dirs,
    pdf: PdfFunc,
    *,
    frame=None,
    theta_edges=None,
    phi_edges=None,
    subdivisions: int = 1,
    order: int = 4,
    alpha: float = 0.01,
    test_count: int = 1,
    min_expected: float = 5.0,
    max_depth: int = 10,
) -> ChiSquareResult:
    """Chi-square test of unit directions ``dirs`` (N, 3) against ``pdf`` (per steradian) on the sphere.

    By default cells are 64 uniform rings in cos(theta) times 128 sectors in phi (Mitsuba's layout).
    Non-finite or non-unit directions fail the test.
    """
    d = np.asarray(dirs, dtype=np.float64)
    n = d.shape[0]
    norm = np.linalg.norm(d, axis=1)
    if not np.all(np.isfinite(d)) or not np.allclose(norm, 1.0, atol=1e-6):
        bad = int(np.sum(~np.isfinite(norm) | (np.abs(norm - 1.0) > 1e-6)))
        return ChiSquareResult(np.inf, 0, 0.0, alpha, False, f"{bad} samples are not finite unit vectors", np.nan)
    te = np.arccos(np.linspace(1.0, -1.0, 65)) if theta_edges is None else np.asarray(theta_edges)
    pe = np.linspace(0.0, 2.0 * np.pi, 129) if phi_edges is None else np.asarray(phi_edges)
    counts = spherical_counts(d, te, pe, frame=frame)
    expected = n * spherical_expected(
        pdf,
        te,
        pe,
        frame=frame,
        subdivisions=subdivisions,
        order=order,
        atol=0.01 / n,
        refine=counts > 0,
        max_depth=max_depth,
    )
    return goodness_of_fit(counts, expected, alpha=alpha, test_count=test_count, min_expected=min_expected)


# --- ready-made checks for lightprobe's samplers ---------------------------------------------------------------
#: Rows (s, t, n) mapping an environment's frame to the chi-square frame, so that the test's (theta, phi) are the
#: lat-long (pi v, 2 pi u): local x = -z_env, local y = x_env, local z = y_env.
ENV_TO_LATLONG_ANGLES = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def check_bsdf_sampling(
    bsdf, wo, *, n: int = 1_000_000, seed: int = 0, rings: int = 64, sectors: int = 128, **kwargs
) -> ChiSquareResult:
    """Chi-square test of ``bsdf.sample`` against ``bsdf.pdf`` for one local ``wo``.

    Cells are equal-mass rings about the mirror direction (merged with uniform rings) times uniform sectors, so
    lobes of any width are resolved.  ``kwargs`` go to :func:`spherical_test` (alpha, test_count, ...).
    """
    from ..geometry.frame import frame_matrix

    wo = np.asarray(wo, dtype=np.float64)
    u = np.random.default_rng(seed).random((n, 3))
    wi, pdf = bsdf.sample(wo, u)
    valid = pdf > 0  # a sampler may decline (pdf 0); those samples are not part of its density

    def density(v):
        return bsdf.pdf(wo, v)

    frame = frame_matrix(np.array([-wo[0], -wo[1], wo[2]]))
    edges = equal_mass_theta_edges(density, rings, frame=frame)
    phi = np.linspace(0.0, 2.0 * np.pi, sectors + 1)
    return spherical_test(wi[valid], density, frame=frame, theta_edges=edges, phi_edges=phi, **kwargs)


def check_envmap_sampling(
    env,
    *,
    n: int = 1_000_000,
    seed: int = 0,
    compensated: bool = False,
    cells: tuple[int, int] | None = None,
    **kwargs,
) -> ChiSquareResult:
    """Chi-square test of ``env.sample`` against ``env.pdf`` with cells aligned to the PDF grid (``env.pdf_grid``).

    ``cells = (rows, columns)`` either groups whole grid cells or splits each evenly (the default splits small
    grids into at least 32 x 64 cells, which tests the placement of samples *inside* a cell, and groups large
    grids into at most 128 x 256).  Aligned cells make the quadrature of a piecewise-constant pdf exact.  A
    ``pdf='bilinear'`` map is tested on its own pieces instead (``cells`` does not apply).
    """
    if getattr(env, "pdf_mode", None) == "bilinear":
        if cells is not None:
            raise ValueError("cells applies to piecewise-constant PDFs; a bilinear one is tested on its pieces")
        theta, phi, subdivisions = _bilinear_cells(env)
    else:
        width, height = env.pdf_grid  # the cells of the piecewise-constant pdf (finer than the image)
        if cells is None:
            rows = height * max(1, 32 // height) if height < 32 else min(height, 128)
            cols = width * max(1, 64 // width) if width < 64 else min(width, 256)
            cells = (rows, cols)
        rows, cols = cells
        theta = texel_edges(height, rows, np.pi)
        phi = texel_edges(width, cols, 2.0 * np.pi)
        subdivisions = max(1, height // rows)
    u = np.random.default_rng(seed).random((n, 2))
    dirs, _ = env.sample(u, compensated=compensated)
    frame = ENV_TO_LATLONG_ANGLES @ env.to_world.T
    kwargs.setdefault("order", 2)
    kwargs.setdefault("max_depth", 0)  # aligned parts: the quadrature is already exact, refining only costs time
    return spherical_test(
        dirs,
        lambda v: env.pdf(v, compensated=compensated),
        frame=frame,
        theta_edges=theta,
        phi_edges=phi,
        subdivisions=subdivisions,
        **kwargs,
    )


def _split_edges(edges: np.ndarray, parts: int) -> np.ndarray:
    """Each interval of ``edges`` split into ``parts`` equal ones."""
    t = np.arange(parts) / parts
    inner = edges[:-1, None] + (edges[1:] - edges[:-1])[:, None] * t[None, :]
    return np.append(inner.reshape(-1), edges[-1])


def _bilinear_cells(env) -> tuple[np.ndarray, np.ndarray, int]:
    """The bilinear density's cells: its pieces (``env.pdf_pieces()``, where pdf x sin(theta) is bilinear, so
    2-point Gauss rules are exact), each split evenly until there are at least 32 x 64 cells; no subdivision."""
    theta, phi = env.pdf_pieces()
    theta = _split_edges(theta, max(1, -(-32 // (theta.size - 1))))
    phi = _split_edges(phi, max(1, -(-64 // (phi.size - 1))))
    return theta, phi, 1
