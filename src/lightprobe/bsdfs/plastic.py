"""Rough plastic: a diffuse base under a rough dielectric coating (GGX), as Mitsuba 3's ``roughplastic``.

::

    f = f_s + f_d
    f_s = F(dot(wi, h), eta) D(h) G1(wi, h) G1(wo, h) / (4 cos(theta_i) cos(theta_o))          (specular coat)
    f_d = diffuse / pi * T(cos theta_i) T(cos theta_o) / (eta^2 (1 - F_dr))                   (diffuse substrate)

F is the exact dielectric Fresnel term.  T(mu) is the transmittance of the rough interface into the substrate
(Fresnel transmission times the masking of the refracted direction, averaged over visible normals); F_dr, about
2 * integral of R_int(mu) mu dmu, is the diffuse reflectance of the interface seen from inside (index 1/eta), which
sends light back to the substrate again and again.  Both are tabulated at construction exactly as Mitsuba 3 does
(T at 64 evenly spaced mu in [0, 1], linearly interpolated), so the diffuse lobe matches its ``roughplastic``.

Parameters
----------
diffuse : float or RGB
    Diffuse reflectance of the substrate, in [0, 1].
alpha : float
    GGX roughness of the coating, in [1e-4, 1].
eta : float
    Relative index of refraction of the coating (default 1.49 / 1.000277, Mitsuba's polypropylene in air).

Sampling picks the specular lobe with probability (1 - T(wo)) w / ((1 - T(wo)) w + T(wo) (1 - w)),
w = 1 / (1 + mean diffuse) (Mitsuba's weighting), else a cosine-weighted direction; ``pdf`` is the mixture.  The
choice is made by the direction's second number, rescaled into the chosen lobe's share (see ``bsdfs/base.py``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .._numba import jit, jit_alloc, jit_inline
from ..errors import ParameterError
from ..sampling.distributions import choose_rescaled
from ..sampling.kernels import INV_PI, cosine_hemisphere_pdf
from .base import BSDF, rgb_param
from .conductor import check_alpha, ggx_microfacet_product, ggx_reflection_pdf
from .fresnel import fresnel_dielectric
from .microfacet import ggx_g1, ggx_sample_visible_normal, specular_or_diffuse_direction

__all__ = ["PLASTIC", "RoughPlastic"]

PLASTIC = 3
TABLE_SIZE = 64
# parameter block: diffuse[0:3], alpha[3], eta[4], specular weight[5], 1/(eta^2 (1 - F_dr))[6], T table[8:72]
_ALPHA, _ETA, _WS, _NORM, _TABLE = 3, 4, 5, 6, 8


@jit
def _transmittance(p, mu):
    x = min(max(mu, 0.0), 1.0) * (TABLE_SIZE - 1)
    i = min(int(x), TABLE_SIZE - 2)
    t = x - i
    return (1.0 - t) * p[_TABLE + i] + t * p[_TABLE + i + 1]


@jit_inline
def _specular(p, wo, wi):
    k, cos_h = ggx_microfacet_product(p[_ALPHA], wo, wi)
    if k == 0.0:
        return 0.0
    return fresnel_dielectric(cos_h, p[_ETA]) * k


@jit_inline
def plastic_eval(p, wo, wi):
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0, 0.0, 0.0
    s = _specular(p, wo, wi)
    k = _transmittance(p, wi[2]) * _transmittance(p, wo[2]) * p[_NORM] * INV_PI
    return s + p[0] * k, s + p[1] * k, s + p[2] * k


@jit
def _specular_probability(p, wo):
    t = _transmittance(p, wo[2])
    ws = p[_WS]
    return (1.0 - t) * ws / ((1.0 - t) * ws + t * (1.0 - ws))


@jit_inline
def plastic_pdf(p, wo, wi):
    if wo[2] <= 0.0:
        return 0.0
    ps = _specular_probability(p, wo)
    return ps * ggx_reflection_pdf(p[_ALPHA], wo, wi) + (1.0 - ps) * cosine_hemisphere_pdf(wi[0], wi[1], wi[2])


# a function of its own, not inlined: the setup stage that calls it compiles 4 s sooner (decisions.md 112)
@jit
def plastic_sample(p, wo, u0, u1, u2):
    zero = (0.0, 0.0, 0.0)
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, zero
    # the lobe from the pair's second coordinate, rescaled (choose_rescaled): u0, a number of its own, would give
    # each lobe a scattered subset of the pair's stratified set
    specular, v = choose_rescaled(u2, _specular_probability(p, wo))
    wi = specular_or_diffuse_direction(p[_ALPHA], wo, specular, u1, v)
    pdf = plastic_pdf(p, wo, wi)
    if pdf <= 0.0 or wi[2] <= 0.0:
        return wi, pdf, zero
    f = plastic_eval(p, wo, wi)
    k = wi[2] / pdf
    return wi, pdf, (f[0] * k, f[1] * k, f[2] * k)


@jit_alloc
def _interface_albedo(alpha, eta, mus, nodes, weights, transmit):
    """Directional reflectance (or transmittance) of a rough GGX dielectric interface for cos(theta) = mus.

    Integrates over visible normals m ~ D_wo on the unit square with a Gauss-Legendre rule:
    reflection: E[F(wo.m) G1(wi, m)] with wi reflected above the surface;
    transmission: E[(1 - F(wo.m)) G1(wt, m)] with wt refracted below it.
    """
    out = np.empty(mus.shape[0])
    n = nodes.shape[0]
    for k in range(mus.shape[0]):
        mu = max(mus[k], 1e-6)
        ox, oz = math.sqrt(max(0.0, 1.0 - mu * mu)), mu
        acc = 0.0
        for i in range(n):
            for j in range(n):
                mx, my, mz = ggx_sample_visible_normal(alpha, ox, 0.0, oz, nodes[i], nodes[j])
                c = ox * mx + oz * mz
                f = fresnel_dielectric(c, eta)
                if transmit:
                    sin2_t = (1.0 - c * c) / (eta * eta)
                    if sin2_t >= 1.0:
                        continue
                    k_m = c / eta - math.sqrt(1.0 - sin2_t)
                    wx, wy, wz = -ox / eta + k_m * mx, k_m * my, -oz / eta + k_m * mz
                    if wz >= 0.0:
                        continue
                    value = (1.0 - f) * ggx_g1(alpha, wx, wy, wz, mx, my, mz)
                else:
                    wx, wy, wz = 2.0 * c * mx - ox, 2.0 * c * my, 2.0 * c * mz - oz
                    if wz <= 0.0:
                        continue
                    value = f * ggx_g1(alpha, wx, wy, wz, mx, my, mz)
                acc += value * weights[i] * weights[j]
        out[k] = acc
    return out


def _gauss_legendre_unit(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def coating_tables(alpha: float, eta: float) -> tuple[np.ndarray, float]:
    """(T(mu) at 64 evenly spaced mu, F_dr) for a GGX dielectric coating, defined as Mitsuba 3 does.

    T(mu) is the masked transmittance into the substrate (32 x 32 Gauss-Legendre nodes over visible normals);
    F_dr = 2 * mean over the same 64 mu of mu R_int(mu), R_int the reflectance from inside (index 1/eta,
    128 x 128 nodes, for total internal reflection).  A coating's tables are made once per process (1.1 million
    quadrature nodes, 11 ms): a session that loads scenes again and again (the suite's 500 scene-file checks)
    looks them up.
    """
    transmittance, f_dr = _coating_tables(float(alpha), float(eta))
    return transmittance.copy(), f_dr


@functools.lru_cache(maxsize=256)
def _coating_tables(alpha: float, eta: float) -> tuple[np.ndarray, float]:
    mus = np.linspace(0.0, 1.0, TABLE_SIZE)
    transmittance = _interface_albedo(alpha, eta, mus, *_gauss_legendre_unit(32), True)
    internal = _interface_albedo(alpha, 1.0 / eta, mus, *_gauss_legendre_unit(128), False)
    f_dr = float(2.0 * np.mean(internal * np.maximum(mus, 1e-6)))
    return transmittance, f_dr


class RoughPlastic(BSDF):
    """Diffuse substrate under a rough GGX dielectric coating.  See the module docstring."""

    kind = PLASTIC

    def __init__(self, diffuse=0.5, alpha=0.1, *, eta: float = 1.49 / 1.000277):
        super().__init__()
        self.diffuse = rgb_param(diffuse, "diffuse", upper=1.0)
        self.alpha = check_alpha(alpha)
        eta = float(eta)
        if not (math.isfinite(eta) and eta > 1.0):
            raise ParameterError(f"eta must be a finite number > 1, got {eta}")
        self.eta = eta
        self.transmittance, self.internal_reflectance = coating_tables(self.alpha, eta)
        self.params[0:3] = self.diffuse
        self.params[_ALPHA] = self.alpha
        self.params[_ETA] = eta
        self.params[_WS] = 1.0 / (1.0 + float(self.diffuse.mean()))
        self.params[_NORM] = 1.0 / (eta * eta * (1.0 - self.internal_reflectance))
        self.params[_TABLE : _TABLE + TABLE_SIZE] = self.transmittance

    def diffuse_factor(self, mu) -> np.ndarray:
        """g(mu) = T(mu) / (eta sqrt(1 - F_dr)), so that f_d = diffuse/pi g(cos_i) g(cos_o) (scene.json's form)."""
        t = np.interp(np.asarray(mu, dtype=np.float64), np.linspace(0, 1, TABLE_SIZE), self.transmittance)
        return t / (self.eta * math.sqrt(1.0 - self.internal_reflectance))

    def __repr__(self) -> str:
        return f"RoughPlastic(diffuse={self.diffuse.tolist()}, alpha={self.alpha:g}, eta={self.eta:g})"
