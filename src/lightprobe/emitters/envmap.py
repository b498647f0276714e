"""Environment map: an HDR image of radiance arriving from infinitely far away, with importance sampling.

Parameters (keyword-only options of :meth:`EnvironmentMap.load` and :meth:`EnvironmentMap.from_array`)
-----------------------------------------------------------------------------------------------------------
mapping : {"latlong", "angular"}
    Layout of the input image (see :mod:`lightprobe.emitters.mappings`).  Angular maps (Debevec's light probes)
    are resampled once to lat-long (height = size/2, width = size, 4x4 supersampling); everything else works on
    the lat-long image, so radiance lookups and the sampling PDF describe the same function.
scale : float
    Multiplies the radiance (> 0).
rotation : None, float or (3, 3) array
    Environment-to-world rotation: an angle in degrees about +Y, or a rotation matrix.
lookup : {"bilinear", "nearest"}
    Radiance reconstruction.  ``bilinear`` follows Mitsuba 3 exactly (columns at u = (i + 0.5)/W, rows at
    v = j/(H - 1)); ``nearest`` returns the texel that contains the direction, the piecewise-constant function that
    the sampling PDF is exactly proportional to.  A map whose texels are all the same (a scene file's
    ``constant``) returns that radiance either way without computing the direction's coordinates, as pbrt-v4's
    ``UniformInfiniteLight`` (decisions.md 100).
pdf : {"bilinear", "exact", "pbrt"}
    ``bilinear`` (default with bilinear lookups, unless ``pdf_weights`` or ``pdf_resolution`` is given): the
    density is the lookup's own bilinear luminance, weighted by sin(theta) at the nodes, as Mitsuba 3 samples its
    maps (:mod:`lightprobe.emitters.envmap_bilinear`); L / p is then nearly constant even across a bilinearly spread
    sun (peer scene: 1.18x lower error than ``exact`` at equal samples).  ``pdf_weights`` and ``pdf_resolution``
    do not apply to it.  ``exact`` (Krivanek, default otherwise): texel probability = luminance x the texel's solid
    angle dphi (cos theta0 - cos theta1), and the direction is uniform *on the sphere* inside the texel (phi
    uniform, cos theta uniform), so p(w) = luminance(texel) / integral of luminance: exactly proportional, no
    pixel-centre or half-texel bias.  ``pbrt``: texel probability = luminance x sin(theta at the row centre),
    (u, v) uniform inside the texel, and p(w) = p(u, v) W H / (2 pi^2 sin theta) with the direction's own theta.
pdf_weights : {"bilinear", "texel", "blur"}
    The luminance the PDF is built from, per texel.  ``texel``: the texel's own luminance (the function the
    ``exact`` PDF is exactly proportional to with ``nearest`` lookups).  ``bilinear``: the mean over the texel of
    the bilinear reconstruction (4 x 4 points), plus 1e-4 x the blurred luminance so that every direction with
    non-zero radiance keeps non-zero density; this follows the bilinear radiance far more closely (measured on the
    peer scene's sun: 2x less error on the sunlit ground at equal samples than the blur).  ``blur``: pbrt's
    slightly blurred luminance, [1 2 1] x [1 2 1] / 16 (wrapping in u), whose reason is the same support
    guarantee.  Default: ``bilinear`` for bilinear lookups, ``texel`` for nearest.

Two distributions are built: the plain one, and the MIS-compensated one (Karlik et al. 2019, as pbrt-v4:
subtract the solid-angle mean luminance, clamp at zero; falls back to the plain one for a constant map).  The
compensated PDF is zero on dim texels, so it is only valid combined with BSDF sampling under MIS:
``sample(u, compensated=True)``, ``pdf(dirs, compensated=True)``.

Input hygiene: NaN or infinite texels are an :class:`~lightprobe.errors.ImageError` naming the file; negative
values (lossy EXR compression rings) are clamped to 0 with a :class:`~lightprobe.errors.LightprobeWarning`; a map
that is black everywhere is rejected (nothing could be lit and there is no distribution to sample).
"""

from __future__ import annotations

import functools
import math
import numbers
import os
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._memory import fresh_array
from .._numba import jit, jit_inline
from .._worksharing import in_threads, read_only
from ..errors import ImageError, ParameterError, warn_once
from ..sampling.distributions import invert_2d, pdf_2d, sample_2d
from ..sampling.kernels import TWO_PI
from . import mappings
from .envmap_bilinear import (
    SMALL_ANGLE_COLUMNS,
    SMALL_ANGLE_ROWS,
    angle_tables,
    bilinear_invert,
    bilinear_pdf,
    bilinear_sample,
    build_bilinear,
    sample_angles,
)
from .envmap_pdf import build_distributions, luminance_f32
from .kinds import LightSample
from .mappings import bilinear_latlong, direction_to_latlong, nearest_latlong

__all__ = ["EnvKernel", "EnvironmentMap", "placeholder_environment"]

LOOKUPS = {"nearest": 0, "bilinear": 1}
PDF_MODES = {"exact": 0, "pbrt": 1, "bilinear": 2}
_REFINE_UP_TO = 2048 * 1024  # texels: maps up to 2K get a PDF grid 2x finer in each dimension
PDF_WEIGHTS = ("bilinear", "texel", "blur")
EXACT, PBRT, BILINEAR_PDF = 0, 1, 2
NEAREST, BILINEAR = 0, 1


class EnvKernel(NamedTuple):
    """Arrays the Numba kernels need (built once by :class:`EnvironmentMap`)."""

    image: np.ndarray  # (H, W, 3) float32 radiance, scale applied
    to_env: np.ndarray  # (3, 3) world -> environment frame
    to_world: np.ndarray  # (3, 3) environment -> world frame
    lookup: int
    mode: int
    cos_edges: np.ndarray  # (rows + 1,) cos(theta) at the row boundaries of the PDF grid
    marginal_cdf: np.ndarray  # (rows + 1,)
    conditional_cdf: np.ndarray  # (rows, columns + 1)
    comp_marginal_cdf: np.ndarray
    comp_conditional_cdf: np.ndarray
    # pdf="bilinear" (emitters/envmap_bilinear.py): the two densities' running sums sit in the *_cdf fields above
    # (marginal (NY,), rows (NY, W + 1)); node weights come from this luminance
    luminance: np.ndarray  # (H, W) float32, unscaled
    node_sines: np.ndarray  # (NY,)
    comp_offset: float  # luminance subtracted by the compensated density
    row_angles: np.ndarray  # (NY, 2) cos, sin of the node rows' theta (envmap_bilinear.angle_tables)
    column_angles: np.ndarray  # (W, 2) cos, sin of the columns' phi
    # guide tables of the two bilinear densities' searches (envmap_bilinear.BilinearDensity), int32
    marginal_guide: np.ndarray  # (G + 1,)
    row_guide: np.ndarray  # (NY, G + 1)
    comp_marginal_guide: np.ndarray
    comp_row_guide: np.ndarray
    uniform: bool  # every texel the same radiance (a scene file's ``constant``): lookups need no coordinates


# --- kernels ------------------------------------------------------------------------------------------------------
@jit
def _mat_vec(m, x, y, z):
    return (
        m[0, 0] * x + m[0, 1] * y + m[0, 2] * z,
        m[1, 0] * x + m[1, 1] * y + m[1, 2] * z,
        m[2, 0] * x + m[2, 1] * y + m[2, 2] * z,
    )


@jit_inline
def _uniform_radiance(k):
    return float(k.image[0, 0, 0]), float(k.image[0, 0, 1]), float(k.image[0, 0, 2])


@jit_inline
def _lookup(k, u, v):
    if k.uniform:
        return _uniform_radiance(k)
    if k.lookup == BILINEAR:
        return bilinear_latlong(k.image, u, v)
    return nearest_latlong(k.image, u, v)


@jit_inline
def env_eval(k, x, y, z):
    """Radiance (r, g, b) arriving from world direction (x, y, z)."""
    if k.uniform:  # a constant map sees the same every way: no lat-long coordinates (an atan2 and an acos)
        return _uniform_radiance(k)
    ex, ey, ez = _mat_vec(k.to_env, x, y, z)
    u, v = direction_to_latlong(ex, ey, ez)
    return _lookup(k, u, v)


@jit_inline
def _cdfs(k, compensated):
    if compensated:
        return k.comp_marginal_cdf, k.comp_conditional_cdf
    return k.marginal_cdf, k.conditional_cdf


@jit_inline
def _offset(k, compensated):
    return k.comp_offset if compensated else 0.0


@jit_inline
def _bilinear_x(k, u):
    """The bilinear density's coordinate u' = u - 0.5 / W (wrapped) of lat-long u."""
    x = u - 0.5 / k.luminance.shape[1]
    return x + 1.0 if x < 0.0 else x


@jit_inline
def _cell_pdf(k, joint_density, row, sin_theta):
    """Solid-angle density from a unit-square density (eqs. in the module docstring): per cell for ``exact``,
    with the lat-long Jacobian 1 / (2 pi^2 sin theta) for ``pbrt`` and ``bilinear``."""
    h = k.marginal_cdf.shape[0] - 1
    if k.mode == EXACT:
        return joint_density / (TWO_PI * h * (k.cos_edges[row] - k.cos_edges[row + 1]))
    if sin_theta <= 0.0:
        return 0.0
    return joint_density / (2.0 * math.pi * math.pi * sin_theta)


@jit_inline
def env_sample_full(k, compensated, u0, u1):
    """Sample a world direction: (x, y, z, pdf, u, y_cell, cos_theta), the last three being what
    :func:`env_radiance_at_sample` needs to look the radiance up without converting the direction back."""
    mc, cc = _cdfs(k, compensated)
    if k.mode == BILINEAR_PDF:
        x, y, p, column, tx, node_row, t = bilinear_sample(
            k.luminance, k.node_sines, _offset(k, compensated), cc, mc, u0, u1
        )
        x += 0.5 / k.luminance.shape[1]  # node i sits at the lookup's column centre u = (i + 0.5) / W
        if x >= 1.0:
            x -= 1.0
        row = 0  # unused: the density is per (u, v), converted like pbrt's
        if k.row_angles.shape[0] >= SMALL_ANGLE_ROWS and k.column_angles.shape[0] >= SMALL_ANGLE_COLUMNS:
            cos_theta, sin_phi, cos_phi = sample_angles(k.row_angles, k.column_angles, node_row, t, column, tx)
        else:
            cos_theta = math.cos(math.pi * y)
            sin_phi, cos_phi = math.sin(TWO_PI * x), math.cos(TWO_PI * x)
    else:
        x, y, p, _, row = sample_2d(mc, cc, u0, u1)
        h = mc.shape[0] - 1
        if k.mode == EXACT:
            # uniform in cos(theta) between the row's edges: uniform in solid angle inside the cell
            t = min(max(y * h - row, 0.0), 1.0)
            c0 = k.cos_edges[row]
            cos_theta = c0 - t * (c0 - k.cos_edges[row + 1])
        else:
            cos_theta = math.cos(math.pi * y)
        sin_phi, cos_phi = math.sin(TWO_PI * x), math.cos(TWO_PI * x)
    sin_theta = math.sqrt(max(0.0, (1.0 - cos_theta) * (1.0 + cos_theta)))
    wx, wy, wz = _mat_vec(k.to_world, sin_phi * sin_theta, cos_theta, -cos_phi * sin_theta)
    return wx, wy, wz, _cell_pdf(k, p, row, sin_theta), x, y, cos_theta


@jit_inline
def env_sample(k, compensated, u0, u1):
    """Sample a world direction: returns (x, y, z, pdf per steradian)."""
    wx, wy, wz, pdf, _, _, _ = env_sample_full(k, compensated, u0, u1)
    return wx, wy, wz, pdf


@jit_inline
def env_radiance_at_sample(k, u, y, cos_theta):
    """Radiance in the direction :func:`env_sample_full` returned with (u, y, cos_theta)."""
    return _lookup(k, u, env_sample_coords(k, y, cos_theta))


@jit_inline
def _pdf_at(k, compensated, u, v, ey):
    mc, cc = _cdfs(k, compensated)
    if k.mode == BILINEAR_PDF:
        sin_theta = math.sqrt(max(0.0, (1.0 - ey) * (1.0 + ey)))
        if sin_theta <= 0.0:
            return 0.0
        p = bilinear_pdf(k.luminance, k.node_sines, _offset(k, compensated), mc, _bilinear_x(k, u), v)
        return _cell_pdf(k, p, 0, sin_theta)
    h = mc.shape[0] - 1
    row = min(int(v * h), h - 1)
    p = pdf_2d(mc, cc, u, (row + 0.5) / h)
    return _cell_pdf(k, p, row, math.sqrt(max(0.0, (1.0 - ey) * (1.0 + ey))))


@jit_inline
def env_pdf(k, compensated, x, y, z):
    """Density per steradian of sampling world direction (x, y, z)."""
    ex, ey, ez = _mat_vec(k.to_env, x, y, z)
    u, v = direction_to_latlong(ex, ey, ez)
    return _pdf_at(k, compensated, u, v, ey)


@jit_inline
def env_coords(k, x, y, z):
    """(u, v, cos theta in the env frame) of a world direction: what :func:`env_lookup` and
    :func:`env_pdf_at` take."""
    ex, ey, ez = _mat_vec(k.to_env, x, y, z)
    u, v = direction_to_latlong(ex, ey, ez)
    return u, v, ey


@jit_inline
def env_lookup(k, u, v):
    """Radiance at lat-long coordinates (u, v)."""
    return _lookup(k, u, v)


@jit_inline
def env_pdf_at(k, compensated, u, v, cos_theta):
    """Density per steradian at lat-long coordinates (u, v) (with the direction's cos theta)."""
    return _pdf_at(k, compensated, u, v, cos_theta)


@jit_inline
def env_sample_coords(k, y, cos_theta):
    """Lat-long v of a sample from :func:`env_sample_full` (y and cos theta as it returned them)."""
    return y if k.mode != EXACT else math.acos(min(1.0, max(-1.0, cos_theta))) / math.pi


@jit_inline
def env_eval_pdf(k, compensated, x, y, z):
    """env_eval and env_pdf in one: ((r, g, b), pdf), converting the direction once."""
    ex, ey, ez = _mat_vec(k.to_env, x, y, z)
    u, v = direction_to_latlong(ex, ey, ez)
    return _lookup(k, u, v), _pdf_at(k, compensated, u, v, ey)


@jit_inline
def env_to_square(k, compensated, x, y, z):
    """The (u0, u1) that ``env_sample`` maps to world direction (x, y, z)."""
    ex, ey, ez = _mat_vec(k.to_env, x, y, z)
    u, v = direction_to_latlong(ex, ey, ez)
    mc, cc = _cdfs(k, compensated)
    if k.mode == BILINEAR_PDF:
        return bilinear_invert(k.luminance, k.node_sines, _offset(k, compensated), cc, mc, _bilinear_x(k, u), v)
    h = mc.shape[0] - 1
    if k.mode == EXACT:
        row = min(int(v * h), h - 1)
        c0 = k.cos_edges[row]
        t = min(max((c0 - ey) / (c0 - k.cos_edges[row + 1]), 0.0), 1.0 - 1e-12)
        v = (row + t) / h
    return invert_2d(mc, cc, u, v)


# The batches (the Python methods' and the tests'): serial range kernels that ``_worksharing.in_threads`` runs in
# threads, not ``prange`` loops, whose parallel passes compiled for longer (decisions.md 129, 130); any split of the
# rows gives the same values.
@jit
def _eval_range(k, dirs, out, lo, hi):
    for i in range(lo, hi):
        out[i, 0], out[i, 1], out[i, 2] = env_eval(k, dirs[i, 0], dirs[i, 1], dirs[i, 2])


def _eval_batch(k, dirs):
    out = np.empty((dirs.shape[0], 3))
    in_threads(_eval_range, dirs.shape[0], k, dirs, out)
    return out


@jit
def _sample_range(k, compensated, u, dirs, pdf, lo, hi):
    for i in range(lo, hi):
        dirs[i, 0], dirs[i, 1], dirs[i, 2], pdf[i] = env_sample(k, compensated, u[i, 0], u[i, 1])


def _sample_batch(k, compensated, u):
    dirs, pdf = np.empty((u.shape[0], 3)), np.empty(u.shape[0])
    in_threads(_sample_range, u.shape[0], k, compensated, u, dirs, pdf)
    return dirs, pdf


@jit
def _pdf_range(k, compensated, dirs, out, lo, hi):
    for i in range(lo, hi):
        out[i] = env_pdf(k, compensated, dirs[i, 0], dirs[i, 1], dirs[i, 2])


def _pdf_batch(k, compensated, dirs):
    out = np.empty(dirs.shape[0])
    in_threads(_pdf_range, dirs.shape[0], k, compensated, dirs, out)
    return out


@jit
def _to_square_range(k, compensated, dirs, out, lo, hi):
    for i in range(lo, hi):
        out[i, 0], out[i, 1] = env_to_square(k, compensated, dirs[i, 0], dirs[i, 1], dirs[i, 2])


def _to_square_batch(k, compensated, dirs):
    out = np.empty((dirs.shape[0], 2))
    in_threads(_to_square_range, dirs.shape[0], k, compensated, dirs, out)
    return out


# --- construction helpers ---------------------------------------------------------------------------------------------
def _rotation_matrix(rotation) -> np.ndarray:
    if rotation is None:
        return np.eye(3)
    if isinstance(rotation, int | float | np.integer | np.floating):
        angle = float(rotation)
        if not math.isfinite(angle):
            raise ParameterError(f"rotation must be a finite angle in degrees, got {rotation}")
        a = math.radians(angle)
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    try:
        m = np.asarray(rotation, dtype=np.float64)
    except (TypeError, ValueError):
        m = np.zeros(0)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ParameterError("rotation must be an angle in degrees about +Y or a finite 3x3 matrix")
    if not np.allclose(m @ m.T, np.eye(3), atol=1e-6) or np.linalg.det(m) < 0:
        raise ParameterError("rotation matrix must be a proper rotation (orthonormal, determinant +1)")
    return m


def _cos_edges(rows: int) -> np.ndarray:
    edges = np.cos(np.pi * np.arange(rows + 1) / rows)
    edges[0], edges[-1] = 1.0, -1.0
    return edges


def _row_solid_angles(rows: int, columns: int) -> np.ndarray:
    """Solid angle of one cell in each row of a lat-long grid: dphi (cos theta0 - cos theta1)."""
    edges = _cos_edges(rows)
    return (TWO_PI / columns) * (edges[:-1] - edges[1:])


@jit
def _count_bad(values):
    """(non-finite values, negative values, the lowest value) of a flat array."""
    nonfinite = 0
    negative = 0
    lowest = math.inf
    for x in values:
        if not math.isfinite(x):
            nonfinite += 1
        elif x < 0.0:
            negative += 1
            lowest = min(lowest, float(x))
    return nonfinite, negative, lowest


def _as_rgb(pixels, source: str) -> np.ndarray:
    data = np.asarray(pixels, dtype=np.float32)
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim != 3 or data.shape[0] < 1 or data.shape[1] < 1:
        raise ImageError(f"{source}: expected an image of shape (height, width[, channels]), got {data.shape}")
    channels = data.shape[2]
    if channels == 1:
        data = np.repeat(data, 3, axis=2)
    elif channels == 4:
        data = data[:, :, :3]
    elif channels != 3:
        raise ImageError(f"{source}: expected 1, 3 or 4 channels, got {channels}")
    data = np.ascontiguousarray(data)
    nonfinite, negative, lowest = _count_bad(data.reshape(-1))  # one pass, no full-size temporaries
    if nonfinite:
        bad = int((~np.isfinite(data)).any(axis=2).sum())
        raise ImageError(f"{source}: {bad} texels are NaN or infinite; repair the image first")
    if negative:
        warn_once(f"{source}: clamped {negative} negative values (min {lowest:.3g}) to 0")
        data = np.maximum(data, 0.0)
    return np.ascontiguousarray(data)


class EnvironmentMap:
    """Distant radiance L(w) from a lat-long image, with importance sampling.  See the module docstring.

    Use :meth:`load` or :meth:`from_array`.  All directions are world-space unit vectors (N, 3); ``u`` is
    (N, 2) in [0, 1); pdfs are per steradian.
    """

    def __init__(
        self,
        latlong,
        *,
        scale: float = 1.0,
        rotation=None,
        lookup: str = "bilinear",
        pdf: str | None = None,
        pdf_weights: str | None = None,
        pdf_resolution: int | None = None,
        source: str = "<array>",
        mapping: str = "latlong",
    ):
        if lookup not in LOOKUPS:
            raise ParameterError(f"lookup must be one of {sorted(LOOKUPS)}, got {lookup!r}")
        if pdf is None:  # the density that follows the lookup, unless a piecewise-constant PDF's option is given
            piecewise = lookup == "nearest" or pdf_weights is not None or pdf_resolution is not None
            pdf = "exact" if piecewise else "bilinear"
        if pdf not in PDF_MODES:
            raise ParameterError(f"pdf must be one of {sorted(PDF_MODES)}, got {pdf!r}")
        scale = float(scale)
        if not (math.isfinite(scale) and scale > 0.0):
            raise ParameterError(f"scale must be a finite number > 0, got {scale}")
        image = _as_rgb(latlong, source)
        self.source = source
        self.mapping = mapping
        self.scale = scale
        self.lookup = lookup
        self.pdf_mode = pdf
        self.radiance = image  # unscaled, as read
        self.to_world = _rotation_matrix(rotation)

        lum = luminance_f32(image)
        if not lum.max() > 0.0:
            raise ImageError(f"{source}: the environment map is black everywhere; nothing would be lit")
        h, w = lum.shape
        self.luminance = lum
        self.texel_solid_angle = _row_solid_angles(h, w)
        self.mean_luminance = float(lum.sum(axis=1, dtype=np.float64) @ self.texel_solid_angle) / (4.0 * math.pi)

        if pdf == "bilinear":
            if pdf_weights is not None or pdf_resolution is not None:
                raise ParameterError(
                    "pdf_weights and pdf_resolution shape the piecewise-constant PDFs (pdf='exact' or 'pbrt'); "
                    "pdf='bilinear' is the map's own bilinear luminance"
                )
            self.pdf_weights = None
            self.pdf_resolution = 1
            self.cos_edges = _cos_edges(h)
            sines, self.distribution, self.compensated_distribution = build_bilinear(
                lum, self.mean_luminance, fresh_array
            )
            tables = (
                self.distribution.marginal,
                self.distribution.row_sums,
                self.compensated_distribution.marginal,
                self.compensated_distribution.row_sums,
            )
            comp_offset = self.compensated_distribution.offset
            row_angles, column_angles = angle_tables(sines.shape[0], w)
            guides = (
                self.distribution.marginal_guide,
                self.distribution.row_guide,
                self.compensated_distribution.marginal_guide,
                self.compensated_distribution.row_guide,
            )
        else:
            self._build_piecewise_constant(lum, pdf_weights, pdf_resolution)
            tables = (*self.distribution.kernel_arrays(), *self.compensated_distribution.kernel_arrays())
            sines, comp_offset = np.zeros(2), 0.0
            row_angles, column_angles = np.zeros((2, 2)), np.zeros((1, 2))
            guides = (np.full(2, -1, np.int32), np.full((2, 2), -1, np.int32)) * 2
        self._kernel = EnvKernel(
            image if scale == 1.0 else image * np.float32(scale),  # no copy of a large map when unscaled
            np.ascontiguousarray(self.to_world.T),
            np.ascontiguousarray(self.to_world),
            LOOKUPS[lookup],
            PDF_MODES[pdf],
            self.cos_edges,
            *tables,
            lum,
            sines,
            float(comp_offset),
            row_angles,
            column_angles,
            *guides,
            # every texel the same radiance: a luminance that varies rules a map out without comparing its texels
            bool(lum.min() == lum.max() and np.all(image == image[:1, :1])),
        )

    def _build_piecewise_constant(self, lum, pdf_weights, pdf_resolution):
        h, w = lum.shape
        if pdf_weights is None:
            pdf_weights = "bilinear" if self.lookup == "bilinear" else "texel"
        if pdf_weights not in PDF_WEIGHTS:
            raise ParameterError(f"pdf_weights must be one of {list(PDF_WEIGHTS)}, got {pdf_weights!r}")
        self.pdf_weights = pdf_weights
        if pdf_resolution is None:  # finer cells follow a bilinear sun more closely; large maps need no refining
            pdf_resolution = 2 if h * w <= _REFINE_UP_TO else 1
        f = pdf_resolution
        if isinstance(f, bool) or not isinstance(f, numbers.Integral) or not 1 <= f <= 8:
            raise ParameterError(f"pdf_resolution must be an integer from 1 to 8, got {pdf_resolution!r}")
        f = int(f)
        self.pdf_resolution = f
        cell_solid_angle = _row_solid_angles(h * f, w * f)
        self.cos_edges = _cos_edges(h * f)
        self.distribution, self.compensated_distribution = build_distributions(
            lum, f, pdf_weights, self._row_factor(h * f), cell_solid_angle
        )

    def _row_factor(self, rows: int) -> np.ndarray:
        """Per row, what turns a cell's luminance into its probability weight (cells have equal areas in (u, v)):
        the row's solid angle for ``exact``, sin(theta at the row centre) for ``pbrt``."""
        if self.pdf_mode == "exact":
            return self.cos_edges[:-1] - self.cos_edges[1:]
        return np.sin(np.pi * (np.arange(rows) + 0.5) / rows)

    # --- construction ---------------------------------------------------------------------------------------------
    @classmethod
    def from_array(cls, rgb, *, mapping: str = "latlong", source: str = "<array>", **options) -> EnvironmentMap:
        """Build from an (H, W[, C]) float array in ``mapping`` layout; ``options`` as in the class."""
        if mapping == "latlong":
            return cls(rgb, source=source, mapping=mapping, **options)
        if mapping == "angular":
            data = _as_rgb(rgb, source)
            size = data.shape[0]
            if data.shape[1] != size or size < 2:
                raise ImageError(
                    f"{source}: an angular (light probe) map must be square (at least 2x2), this one is "
                    f"{data.shape[1]}x{data.shape[0]}"
                )
            height = max(1, size // 2)
            latlong = mappings.angular_to_latlong_image(data, height, 2 * height, 4)
            return cls(latlong, source=source, mapping=mapping, **options)
        raise ParameterError(f"mapping must be 'latlong' or 'angular', got {mapping!r}")

    @classmethod
    def load(cls, path: str | os.PathLike, *, mapping: str = "latlong", **options) -> EnvironmentMap:
        """Read a map (see the class for ``options``: scale, rotation, lookup, pdf, ...).

        .exr, .hdr and .pfm hold linear radiance; an 8-bit PNG/JPEG is decoded to linear with a warning (see
        :func:`~lightprobe.images.read_radiance`).  A lat-long map that is not 2:1 loads with a warning (a crop,
        a cube cross or a mirror ball is the usual cause); an angular map must be square.
        """
        from ..images import read_radiance

        source = str(Path(path))
        pixels = read_radiance(path)
        if mapping == "latlong":
            height, width = pixels.shape[:2]
            if abs(width - 2 * height) > max(1, 0.01 * width):
                warn_once(
                    f"{source}: a lat-long map should be twice as wide as it is high, this one is {width}x{height} "
                    f"({width / height:.3g}:1); is it a crop, a cube map or an angular probe (--mapping angular)?"
                )
        return cls.from_array(pixels, mapping=mapping, source=source, **options)

    # --- queries --------------------------------------------------------------------------------------------------
    @property
    def kernel(self) -> EnvKernel:
        """The arrays for Numba kernels (:func:`env_eval`, :func:`env_sample`, :func:`env_pdf`)."""
        return self._kernel

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) of the lat-long image."""
        return self.radiance.shape[1], self.radiance.shape[0]

    def eval(self, dirs) -> np.ndarray:
        """Radiance (N, 3) arriving from world directions ``dirs`` (N, 3)."""
        return _eval_batch(self._kernel, _directions(dirs))

    def sample(self, u, *, compensated: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Map ``u`` (N, 2) to world directions (N, 3) and their pdf per steradian (N,)."""
        return _sample_batch(self._kernel, bool(compensated), _unit_square(u))

    def pdf(self, dirs, *, compensated: bool = False) -> np.ndarray:
        return _pdf_batch(self._kernel, bool(compensated), _directions(dirs))

    # --- the emitter contract (emitters/area.py): the environment is a light whose samples do not depend on the
    # reference point and lie infinitely far away
    def sample_li(self, points, normals, u, *, compensated: bool = False):
        """Directions toward the environment for reference ``points`` (N, 3) with ``normals`` (ignored: the
        map is sampled the same way from everywhere): a :class:`~lightprobe.emitters.area.LightSample` with
        infinite distances."""
        from .area import LightSample

        dirs, pdf = self.sample(u, compensated=compensated)
        return LightSample(dirs, np.full(pdf.shape, np.inf), self.eval(dirs), pdf)

    def pdf_li(self, points, normals, dirs, *, compensated: bool = False) -> np.ndarray:
        """Density per steradian of :meth:`sample_li` producing ``dirs`` (the same from every point)."""
        return self.pdf(dirs, compensated=compensated)

    def to_square(self, dirs, *, compensated: bool = False) -> np.ndarray:
        """Inverse of :meth:`sample`: the ``u`` that produces each direction."""
        return _to_square_batch(self._kernel, bool(compensated), _directions(dirs))

    def integral(self) -> float:
        """Integral of luminance over the sphere (with ``scale``), for the nearest-texel function."""
        return 4.0 * math.pi * self.mean_luminance * self.scale

    @cached_property
    def irradiance_terms(self) -> np.ndarray:
        """(a, bx, by, bz): the irradiance of the luminance to first order, E(n) ~ a + b . n for a surface with
        world normal n.  With L(w) ~ c0 + c1 . w (c0 the mean, c1 = 3 / (4 pi) int L w dw), the cosine-weighted
        hemisphere integral gives a = pi c0 and b = 2 pi / 3 c1.  The light selectors weigh the environment
        against the area lights with it (emitters/selection.py).  Texel centres, nearest-texel quadrature."""
        return self._first_order_irradiance(self.luminance.astype(np.float64))

    @cached_property
    def compensated_irradiance_terms(self) -> np.ndarray:
        """:attr:`irradiance_terms` of the compensated luminance max(L - mean, 0) (Karlik et al. 2019; the mean per
        unit solid angle, as the compensated density subtracts): what a light selector weighs the environment by
        at a receiver that samples the compensated density (emitters/selection.py).  Zero for a constant map."""
        lum = self.luminance.astype(np.float64)
        return self._first_order_irradiance(np.maximum(lum - self.mean_luminance, 0.0))

    def _first_order_irradiance(self, lum: np.ndarray) -> np.ndarray:
        h, w = lum.shape
        theta = np.pi * (np.arange(h) + 0.5) / h
        phi = TWO_PI * (np.arange(w) + 0.5) / w
        weighted = lum * self.texel_solid_angle[:, None]  # L dw per texel
        rows = weighted.sum(axis=1)
        sin_phi, cos_phi = weighted @ np.sin(phi), weighted @ np.cos(phi)
        # local directions (sin phi sin theta, cos theta, -cos phi sin theta), as pdf_image's
        first = np.array([sin_phi @ np.sin(theta), rows @ np.cos(theta), -(cos_phi @ np.sin(theta))])
        c0 = rows.sum() / (4.0 * math.pi)
        c1 = 3.0 / (4.0 * math.pi) * (self.to_world @ first)
        return np.array([math.pi * c0, *(2.0 * math.pi / 3.0 * c1)]) * self.scale

    def pdf_image(self, *, compensated: bool = False) -> np.ndarray:
        """Sampling density per steradian on the PDF grid (``pdf_resolution`` x the image in each dimension;
        at the row centre for ``pdf='pbrt'``; at the texel centres for ``pdf='bilinear'``)."""
        if self.pdf_mode == "bilinear":
            h, w = self.luminance.shape
            v = (np.arange(h) + 0.5) / h
            u = (np.arange(w) + 0.5) / w
            theta, phi = np.pi * v[:, None], 2 * np.pi * u[None, :]
            local = np.stack(
                np.broadcast_arrays(np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)), -1
            )
            return self.pdf(local.reshape(-1, 3) @ self.to_world.T, compensated=compensated).reshape(h, w)
        dist = self.compensated_distribution if compensated else self.distribution
        joint = dist.marginal_density[:, None] * dist.conditional_density
        h = joint.shape[0]
        if self.pdf_mode == "exact":
            return joint / (TWO_PI * h * (self.cos_edges[:-1] - self.cos_edges[1:]))[:, None]
        return joint / (2 * math.pi**2 * np.sin(np.pi * (np.arange(h) + 0.5) / h))[:, None]

    @property
    def pdf_grid(self) -> tuple[int, int]:
        """(columns, rows) of the PDF's pieces: cells of the piecewise-constant PDFs, intervals between the nodes
        of the bilinear one (see :meth:`pdf_pieces`)."""
        if self.pdf_mode == "bilinear":
            return self.luminance.shape[1], self.distribution.row_sums.shape[0] - 1
        return self.distribution.shape[1], self.distribution.shape[0]

    def pdf_pieces(self) -> tuple[np.ndarray, np.ndarray]:
        """(theta edges, phi edges) in radians, environment frame, of the pieces on which pdf x sin(theta) is a
        polynomial of degree <= 1 in each angle (constant for ``exact``/``pbrt`` cells up to the Jacobian,
        bilinear between ``bilinear``'s nodes, whose columns sit at the texel centres): quadrature on these
        pieces is exact."""
        columns, rows = self.pdf_grid
        theta = np.linspace(0.0, np.pi, rows + 1)
        if self.pdf_mode == "bilinear":
            phi = 2 * np.pi * np.concatenate([[0.0], (np.arange(columns) + 0.5) / columns, [1.0]])
        else:
            phi = np.linspace(0.0, 2 * np.pi, columns + 1)
        return theta, phi

    def to_array(self, *, mapping: str = "latlong", size: int | None = None) -> np.ndarray:
        """The radiance image (scale applied, rotation not) as lat-long, or resampled to an angular map."""
        image = self.radiance * np.float32(self.scale)
        if mapping == "latlong":
            return image
        if mapping == "angular":
            side = int(size) if size else self.resolution[0]
            if side < 2:
                raise ParameterError(f"size must be >= 2, got {side}")
            return mappings.latlong_to_angular_image(np.ascontiguousarray(image), side, 4)
        raise ParameterError(f"mapping must be 'latlong' or 'angular', got {mapping!r}")

    def stats(self) -> dict:
        """Resolution, luminance min/max/mean (solid-angle weighted), dynamic range, energy of the top 0.1%."""
        lum = self.luminance * self.scale
        energy = (lum * self.texel_solid_angle[:, None]).reshape(-1)
        order = np.argsort(lum.reshape(-1))[::-1]
        top = max(1, round(0.001 * lum.size))
        positive = lum[lum > 0]
        return {
            "source": self.source,
            "mapping": self.mapping,
            "width": self.resolution[0],
            "height": self.resolution[1],
            "min_luminance": float(lum.min()),
            "max_luminance": float(lum.max()),
            "mean_luminance": float(self.mean_luminance * self.scale),
            "median_luminance": float(np.median(lum)),
            "dynamic_range_stops": float(np.log2(lum.max() / np.percentile(positive, 1))),
            "top_0.1%_energy_fraction": float(energy[order[:top]].sum() / energy.sum()),
            "integral": self.integral(),
        }

    def __repr__(self) -> str:
        w, h = self.resolution
        grid = (
            ""
            if self.pdf_mode == "bilinear"
            else f", pdf_weights={self.pdf_weights!r}, pdf_resolution={self.pdf_resolution}"
        )
        return (
            f"EnvironmentMap({self.source!r}, {w}x{h}, scale={self.scale:g}, lookup={self.lookup!r}, "
            f"pdf={self.pdf_mode!r}{grid})"
        )


def _directions(dirs) -> np.ndarray:
    d = np.asarray(dirs, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3:
        raise ParameterError(f"dirs must be an (N, 3) array, got shape {d.shape}")
    return read_only(np.ascontiguousarray(d))  # one signature of the batch kernels, whatever the caller passed


def _unit_square(u) -> np.ndarray:
    a = np.asarray(u, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 2:
        raise ParameterError(f"u must be an (N, 2) array, got shape {a.shape}")
    return read_only(np.ascontiguousarray(a))


@functools.lru_cache(maxsize=1)
def placeholder_environment() -> EnvironmentMap:
    """An environment for kernels that must be given one when the scene has none (no light row refers to it, so it
    is never looked up)."""
    from .procedural import constant

    return EnvironmentMap.from_array(constant(1.0, width=2, height=1), source="none")


# --- the light contract (lights.py's dispatchers call these, generated from kinds.KINDS) ------------------------------
# Every kind's module has the same three functions, inlined into the dispatchers; each calls the kind's own sampler
# with only its own data (a call taking the environment's record cost a light sample 30-70 ns: decisions.md 91).
@jit
def _environment_sample(env, compensated, u0, u1):
    """A direction from the map's density and the radiance along it: a call of its own, as the other kinds' are."""
    wx, wy, wz, pdf = env_sample(env, compensated, u0, u1)
    r, g, b = env_eval(env, wx, wy, wz)
    return wx, wy, wz, r, g, b, pdf


@jit_inline
def row_sample(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, u0, u1):
    """The environment's :class:`~.kinds.LightSample`: a direction from its (``compensated``) density."""
    wx, wy, wz, r, g, b, pdf = _environment_sample(env, compensated, u0, u1)
    return LightSample(wx, wy, wz, math.inf, r, g, b, pdf, False)


@jit_inline
def row_pdf(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, wx, wy, wz):
    """The environment's density of direction w (inlined: every BSDF ray that escapes asks for it)."""
    return env_pdf(env, compensated, wx, wy, wz)


@jit_inline
def row_radiance(lights, env, l, wx, wy, wz):
    """What the map shows a ray leaving the scene along w."""
    return env_eval(env, wx, wy, wz)
