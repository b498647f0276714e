"""The modified (energy-normalised) Phong BRDF of the seed, Krivanek eq. 4::

    f(wo, wi) = rho_d / pi + rho_s (n + 2) / (2 pi) cos^n(theta_s)     if wo and wi are above the surface, else 0

where theta_s is the angle between wi and the mirror direction of wo (equivalently between wo and the mirror of
wi).

Parameters
----------
rho_d, rho_s : float or RGB
    Diffuse and specular reflectivities in [0, 1]; for energy conservation rho_d + rho_s <= 1 per channel.
exponent : float
    Phong exponent n >= 0.
estimator : {"mixture", "chosen_lobe"}
    How a BSDF sample is weighted.  Sampling first picks a lobe with probability P_d = rho_d / (rho_d + rho_s)
    (on scalar luminance albedos), then samples cos(theta)/pi (diffuse) or (n + 1)/(2 pi) cos^n about the mirror
    direction (specular, seed eqs. 11-13; samples below the horizon are valid and have value 0).  The choice is
    made by the direction's second number, rescaled into the chosen lobe's share (see ``bsdfs/base.py``).

    * ``mixture`` (default): the sample's pdf is the full mixture (seed eq. 19)
      P_d p_d + P_s p_s and its weight f cos / pdf uses the whole BRDF.  This is the density ``pdf()`` returns,
      and the only form that may be combined with other techniques by MIS.
    * ``chosen_lobe``: the seed's section 2.4 estimator: the sample carries only the chosen lobe's value and
      pdf (rho_d/pi with P_d p_d, or the specular lobe with P_s p_s).  Unbiased on its own, but ``sample()``'s
      pdf is then not ``pdf()`` (which stays the true mixture density), so MIS refuses it.
"""

from __future__ import annotations

import math

from .._numba import jit
from ..color import luminance
from ..errors import ParameterError
from ..geometry.frame import coordinate_system, to_world
from ..sampling.distributions import choose_rescaled
from ..sampling.kernels import (
    INV_2PI,
    INV_PI,
    cosine_hemisphere_pdf,
    phong_lobe_pdf,
    square_to_cosine_hemisphere,
    square_to_phong_lobe,
)
from .base import BSDF, rgb_param

__all__ = ["PHONG", "Phong"]

PHONG = 1
ESTIMATORS = {"mixture": 0.0, "chosen_lobe": 1.0}
# parameter block: rho_d[0:3], rho_s[3:6], exponent[6], estimator[7], P(diffuse)[8]
_EXP, _EST, _PD = 6, 7, 8


@jit
def _cos_theta_s(wo, wi):
    """cos of the angle between wi and the mirror direction (-wo.x, -wo.y, wo.z)."""
    return -wo[0] * wi[0] - wo[1] * wi[1] + wo[2] * wi[2]


@jit
def _specular_lobe(p, wo, wi):
    """(n + 2)/(2 pi) cos^n(theta_s), the specular lobe without rho_s."""
    c = _cos_theta_s(wo, wi)
    if c <= 0.0:
        return 0.0
    return (p[_EXP] + 2.0) * INV_2PI * c ** p[_EXP]


@jit
def phong_eval(p, wo, wi):
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0, 0.0, 0.0
    s = _specular_lobe(p, wo, wi)
    return p[0] * INV_PI + p[3] * s, p[1] * INV_PI + p[4] * s, p[2] * INV_PI + p[5] * s


@jit
def _lobe_pdfs(p, wo, wi):
    """(diffuse pdf, specular pdf) of wi, each per steradian and not yet weighted by its selection probability."""
    pd = cosine_hemisphere_pdf(wi[0], wi[1], wi[2])
    ps = phong_lobe_pdf(0.0, 0.0, _cos_theta_s(wo, wi), p[_EXP])
    return pd, ps


@jit
def phong_pdf(p, wo, wi):
    """The mixture density P_d cos/pi + P_s (n+1)/(2 pi) cos^n(theta_s) (seed eq. 19)."""
    if wo[2] <= 0.0:
        return 0.0
    pd, ps = _lobe_pdfs(p, wo, wi)
    return p[_PD] * pd + (1.0 - p[_PD]) * ps


@jit
def phong_sample(p, wo, u0, u1, u2):
    """Returns (wi, pdf, weight); see the module docstring for the two estimators."""
    zero = (0.0, 0.0, 0.0)
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, zero
    p_diffuse = p[_PD]
    # the lobe from the pair's second coordinate, rescaled (choose_rescaled), as the plastic's
    diffuse, v = choose_rescaled(u2, p_diffuse)
    if diffuse:
        wi = square_to_cosine_hemisphere(u1, v)
    else:
        mirror = (-wo[0], -wo[1], wo[2])
        s, t = coordinate_system(mirror[0], mirror[1], mirror[2])
        local = square_to_phong_lobe(u1, v, p[_EXP])
        wi = to_world(s, t, mirror, local[0], local[1], local[2])
    pd, ps = _lobe_pdfs(p, wo, wi)
    if p[_EST] == 0.0:  # mixture
        pdf = p_diffuse * pd + (1.0 - p_diffuse) * ps
        if pdf <= 0.0 or wi[2] <= 0.0:
            return wi, pdf, zero
        f = phong_eval(p, wo, wi)
        k = wi[2] / pdf
        return wi, pdf, (f[0] * k, f[1] * k, f[2] * k)
    # chosen lobe: the sample carries only the chosen lobe's value, divided by that lobe's pdf
    if diffuse:
        pdf = p_diffuse * pd
        if pdf <= 0.0:
            return wi, pdf, zero
        k = wi[2] * INV_PI / pdf
        return wi, pdf, (p[0] * k, p[1] * k, p[2] * k)
    pdf = (1.0 - p_diffuse) * ps
    if pdf <= 0.0 or wi[2] <= 0.0:
        return wi, pdf, zero
    k = _specular_lobe(p, wo, wi) * wi[2] / pdf
    return wi, pdf, (p[3] * k, p[4] * k, p[5] * k)


class Phong(BSDF):
    """Modified Phong BRDF (Krivanek eq. 4).  See the module docstring for the parameters."""

    kind = PHONG

    def __init__(self, rho_d=0.5, rho_s=0.5, exponent=20.0, *, estimator: str = "mixture"):
        super().__init__()
        self.rho_d = rgb_param(rho_d, "rho_d", upper=1.0)
        self.rho_s = rgb_param(rho_s, "rho_s", upper=1.0)
        exponent = float(exponent)
        if not (math.isfinite(exponent) and exponent >= 0.0):
            raise ParameterError(f"exponent must be a finite number >= 0, got {exponent}")
        if estimator not in ESTIMATORS:
            raise ParameterError(f"estimator must be one of {sorted(ESTIMATORS)}, got {estimator!r}")
        d, s = float(luminance(self.rho_d)), float(luminance(self.rho_s))
        if d + s <= 0.0:
            raise ParameterError("rho_d and rho_s are both zero: the material reflects nothing")
        self.exponent = exponent
        self.estimator = estimator
        self.diffuse_probability = d / (d + s)
        self.params[0:3] = self.rho_d
        self.params[3:6] = self.rho_s
        self.params[_EXP] = exponent
        self.params[_EST] = ESTIMATORS[estimator]
        self.params[_PD] = self.diffuse_probability

    def __repr__(self) -> str:
        return (
            f"Phong(rho_d={self.rho_d.tolist()}, rho_s={self.rho_s.tolist()}, exponent={self.exponent:g}, "
            f"estimator={self.estimator!r})"
        )
