"""The Krivanek exercise's techniques as ``numba.njit`` functions: one sample per call, in lightprobe's compiled loops.

The same maths as the exercise's NumPy solutions (``lightprobe exercise init``), written for Numba: ``sample(u, ctx)``
takes one sample's numbers ``u`` ((dimensions,) array) and returns ``(wi, pdf)``; ``pdf(wi, ctx)`` one direction's
density. ``ctx`` is a ``lightprobe.lab.JitContext`` (``wo``, ``normal``, ``frame``, ``position``, ``material``,
``environment``, ``data``). Check and compare them like any technique::

    lightprobe check examples/njit_sampling.py:PhongLobes
    lightprobe check examples/njit_sampling.py:EnvironmentMap
    lightprobe exercise init ex
    lightprobe compare ex/scene.toml --strategies \\
        "mis,lab:mis,mis:examples/njit_sampling.py:PhongLobes+examples/njit_sampling.py:EnvironmentMap" -o report.html

When every technique of a strategy is njit (lightprobe's own count) and the MIS heuristic is a name or an njit
function like :func:`balance_heuristic` below, the laboratory runs its compiled estimator: the calls happen inside
compiled loops, at about the render core's speed (``benchmarks/lab.py``).
"""

import numba
import numpy as np


@numba.njit
def _cosine(u1, u2):
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    z = np.sqrt(max(0.0, 1.0 - u1))
    return r * np.cos(phi), r * np.sin(phi), z


@numba.njit
def _diffuse_probability(material):
    d = (material.rho_d[0] + material.rho_d[1] + material.rho_d[2]) / 3.0
    s = (material.rho_s[0] + material.rho_s[1] + material.rho_s[2]) / 3.0
    return d / (d + s)


@numba.njit
def _phong_pdf(wi, wo, material):
    p_d = _diffuse_probability(material)
    n = material.exponent
    cos_a = max(-wo[0] * wi[0] - wo[1] * wi[1] + wo[2] * wi[2], 0.0)  # wi . mirror(wo)
    return p_d * max(wi[2], 0.0) / np.pi + (1.0 - p_d) * (n + 1.0) / (2.0 * np.pi) * cos_a**n


class CosineHemisphere:
    """Density cos(theta) / pi about the normal (Malley's method)."""

    kind = "bsdf"
    dimensions = 2
    support = "hemisphere"

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        x, y, z = _cosine(u[0], u[1])
        return (x, y, z), z / np.pi

    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        return max(wi[2], 0.0) / np.pi


class PhongLobes:
    """The modified Phong BRDF's two lobes (Krivanek eqs. 10-12, 19): diffuse with probability P_d chosen by u[2],
    else cos^n about the mirror direction; the pdf is the mixture."""

    kind = "bsdf"
    dimensions = 3
    support = "sphere"

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        material = ctx.material
        wo = ctx.wo
        if u[2] < _diffuse_probability(material):
            x, y, z = _cosine(u[0], u[1])
        else:
            mx, my, mz = -wo[0], -wo[1], wo[2]  # the mirror direction
            sign = 1.0 if mz >= 0.0 else -1.0  # a frame about it (Duff et al. 2017)
            a = -1.0 / (sign + mz)
            b = mx * my * a
            s = (1.0 + sign * mx * mx * a, sign * b, -sign * mx)
            t = (b, sign + my * my * a, -my)
            cos_a = u[0] ** (1.0 / (material.exponent + 1.0))
            sin_a = np.sqrt(max(0.0, 1.0 - cos_a * cos_a))
            phi = 2.0 * np.pi * u[1]
            cs, sn = sin_a * np.cos(phi), sin_a * np.sin(phi)
            x = cs * s[0] + sn * t[0] + cos_a * mx
            y = cs * s[1] + sn * t[1] + cos_a * my
            z = cs * s[2] + sn * t[2] + cos_a * mz
            norm = np.sqrt(x * x + y * y + z * z)
            x, y, z = x / norm, y / norm, z / norm
        wi = np.array((x, y, z))
        return wi, _phong_pdf(wi, wo, material)

    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        return _phong_pdf(wi, ctx.wo, ctx.material)


@numba.njit
def _find_interval(cdf, x):
    """The first index i with cdf[i] > x (cdf increasing, cdf[-1] = 1), at most len(cdf) - 1."""
    lo, hi = 0, cdf.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[mid] > x:
            hi = mid
        else:
            lo = mid + 1
    return lo


@numba.njit
def _map_pdf(density, uu, vv):
    h, w = density.shape
    i = min(int(uu * w), w - 1)
    j = min(int(vv * h), h - 1)
    sin_theta = np.sin(np.pi * vv)
    return density[j, i] / (2.0 * np.pi**2 * sin_theta) if sin_theta > 0.0 else 0.0


class EnvironmentMap:
    """The map as a 2D piecewise-constant distribution (luminance x sin theta per texel), with the lat-long
    Jacobian p(w) = p(u, v) / (2 pi^2 sin theta). ``prepare`` builds the tables in NumPy, once per map, and hands
    them to the njit functions as ``ctx.data``."""

    kind = "light"
    dimensions = 2

    def prepare(self, environment):
        lum = np.asarray(environment.luminance, dtype=np.float64)
        h, w = lum.shape
        weights = lum * np.sin(np.pi * (np.arange(h) + 0.5) / h)[:, None]
        density = weights * (w * h) / weights.sum()
        rows = weights.sum(axis=1)
        marginal = np.cumsum(rows) / rows.sum()
        conditional = np.cumsum(weights, axis=1) / np.maximum(rows, 1e-300)[:, None]
        self.data = (density, marginal, conditional, np.ascontiguousarray(environment.to_world, dtype=np.float64))

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        density, marginal, conditional, rotation = ctx.data
        h, w = density.shape
        j = _find_interval(marginal, u[1])
        row = conditional[j]
        i = _find_interval(row, u[0])
        lo_v = marginal[j - 1] if j > 0 else 0.0
        lo_u = row[i - 1] if i > 0 else 0.0
        dv = min(max((u[1] - lo_v) / max(marginal[j] - lo_v, 1e-300), 0.0), 1.0 - 1e-12)
        du = min(max((u[0] - lo_u) / max(row[i] - lo_u, 1e-300), 0.0), 1.0 - 1e-12)
        uu, vv = (i + du) / w, (j + dv) / h
        theta, phi = np.pi * vv, 2.0 * np.pi * uu
        st = np.sin(theta)
        local = (np.sin(phi) * st, np.cos(theta), -np.cos(phi) * st)
        wi = np.empty(3)
        for k in range(3):  # world = rotation @ local
            wi[k] = rotation[k, 0] * local[0] + rotation[k, 1] * local[1] + rotation[k, 2] * local[2]
        return wi, _map_pdf(density, uu, vv)

    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        density, _, _, rotation = ctx.data
        x = wi[0] * rotation[0, 0] + wi[1] * rotation[1, 0] + wi[2] * rotation[2, 0]  # local = world @ rotation
        y = wi[0] * rotation[0, 1] + wi[1] * rotation[1, 1] + wi[2] * rotation[2, 1]
        z = wi[0] * rotation[0, 2] + wi[1] * rotation[1, 2] + wi[2] * rotation[2, 2]
        uu = np.arctan2(x, -z) / (2.0 * np.pi)
        if uu < 0.0:
            uu += 1.0
        vv = np.arccos(min(max(y, -1.0), 1.0)) / np.pi
        return _map_pdf(density, uu, vv)


@numba.njit
def balance_heuristic(n_f, p_f, n_g, p_g):
    """Veach's balance heuristic for one sample: n_f p_f / (n_f p_f + n_g p_g), 0 where both are 0."""
    a, b = n_f * p_f, n_g * p_g
    return a / (a + b) if a + b > 0.0 else 0.0
