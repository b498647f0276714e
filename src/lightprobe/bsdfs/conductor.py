"""Rough conductor: GGX microfacet reflection (Walter et al. 2007), visible-normal sampling (Heitz 2018).

::

    f(wo, wi) = R F(dot(wi, h)) D(h) G1(wi, h) G1(wo, h) / (4 cos(theta_i) cos(theta_o)),   h = normalize(wi + wo)

with the exact conductor Fresnel term F of complex index eta + i k (per RGB channel), or F = 1 when
``fresnel=False``; R is ``specular_reflectance``.  This matches Mitsuba 3's ``roughconductor`` with
``distribution="ggx"`` and ``sample_visible=true`` (separable Smith G).

Parameters
----------
alpha : float
    GGX roughness in [1e-4, 1].
eta, k : float or RGB
    Complex index of refraction; defaults to aluminium.  ``material`` picks a preset instead.
material : {"Al", "Au", "none"}, optional
    Mitsuba 3.9's RGB values for aluminium and gold; "none" is a perfect reflector (F = 1).
specular_reflectance : float or RGB
    Extra multiplier R (default 1).
fresnel : bool
    Apply the Fresnel term (default True).

Sampling reflects wo about a visible normal m: pdf(wi) = G1(wo, m) D(m) / (4 cos(theta_o)); reflected directions
below the horizon are valid samples with value 0.  The weight is R F G1(wi, m).
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_inline
from ..errors import ParameterError
from .base import BSDF, rgb_param
from .fresnel import fresnel_conductor
from .microfacet import ggx_d_terms, ggx_g1, ggx_g1_denominator, ggx_sample_visible_normal

__all__ = ["CONDUCTOR_PRESETS", "GGX_CONDUCTOR", "GGXConductor", "ggx_reflection_pdf"]

GGX_CONDUCTOR = 2
# Mitsuba 3.9.1's RGB eta/k for its 'Al' and 'Au' presets (as recorded in ../shared/peers/scene.json).
CONDUCTOR_PRESETS = {
    "Al": ((1.6575009, 0.8804047, 0.52124447), (9.223811, 6.269502, 4.837004)),
    "Au": ((0.14303598, 0.37530708, 1.4420453), (3.982997, 2.3855565, 1.6033592)),
}
# parameter block (PARAM_SIZE floats): alpha[0], eta[1:4], k[4:7], specular_reflectance[7:10], fresnel[10]
_ALPHA, _ETA, _K, _R, _FRESNEL = 0, 1, 4, 7, 10


@jit_inline
def _fresnel_rgb(p, cos_theta):
    if p[_FRESNEL] == 0.0:
        return p[_R], p[_R + 1], p[_R + 2]
    return (
        p[_R] * fresnel_conductor(cos_theta, p[_ETA], p[_K]),
        p[_R + 1] * fresnel_conductor(cos_theta, p[_ETA + 1], p[_K + 1]),
        p[_R + 2] * fresnel_conductor(cos_theta, p[_ETA + 2], p[_K + 2]),
    )


@jit
def ggx_reflection_pdf(alpha, wo, wi):
    """Density of wi = reflect(wo, m) with m ~ D_wo: G1(wo, m) D(m) / (4 cos(theta_o)), over the whole sphere.
    With the half vector h = wo + wi unnormalized (microfacet.ggx_d_terms) and G1 = 2 c / (c + r) this is
    alpha^2 |h|^4 / (2 pi e^2 (c + r)): one square root and one division (microfacet.ggx_g1_denominator)."""
    co = wo[2]
    if co <= 0.0:
        return 0.0
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    if hz <= 0.0 or wo[0] * hx + wo[1] * hy + co * hz <= 0.0:  # D(h) = 0, or wo masked by h (G1 = 0)
        return 0.0
    num, e2 = ggx_d_terms(alpha, hx, hy, hz)
    return num / (2.0 * math.pi * e2 * ggx_g1_denominator(alpha, co))


@jit_inline
def ggx_microfacet_product(alpha, wo, wi):
    """D(h) G1(wi, h) G1(wo, h) / (4 cos(theta_i) cos(theta_o)) and cos(wi, h) for wo, wi above the surface, h their
    half vector; (0, 0) where it vanishes. Unnormalized h and G1 = 2 c / (c + r) (microfacet.py) fold the product
    into alpha^2 |h|^4 / (pi e^2 (ci + ri)(co + ro)): three square roots and two divisions where the textbook
    order takes six and eight."""
    ci, co = wi[2], wo[2]
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    di = wi[0] * hx + wi[1] * hy + ci * hz
    if di <= 0.0 or wo[0] * hx + wo[1] * hy + co * hz <= 0.0:  # a direction masked by h (G1 = 0)
        return 0.0, 0.0
    num, e2 = ggx_d_terms(alpha, hx, hy, hz)
    gi, go = ggx_g1_denominator(alpha, ci), ggx_g1_denominator(alpha, co)
    cos_h = di / math.sqrt(hx * hx + hy * hy + hz * hz)
    return num / (math.pi * e2 * gi * go), cos_h


@jit_inline
def ggx_conductor_eval(p, wo, wi):
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0, 0.0, 0.0
    k, cos_h = ggx_microfacet_product(p[_ALPHA], wo, wi)
    if k == 0.0:
        return 0.0, 0.0, 0.0
    f = _fresnel_rgb(p, cos_h)
    return f[0] * k, f[1] * k, f[2] * k


@jit_inline
def ggx_conductor_pdf(p, wo, wi):
    return ggx_reflection_pdf(p[_ALPHA], wo, wi)


# a function of its own, not inlined: the setup stage that calls it compiles 4 s sooner (decisions.md 112)
@jit
def ggx_conductor_sample(p, wo, u0, u1, u2):
    zero = (0.0, 0.0, 0.0)
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, zero
    a = p[_ALPHA]
    mx, my, mz = ggx_sample_visible_normal(a, wo[0], wo[1], wo[2], u1, u2)
    d = wo[0] * mx + wo[1] * my + wo[2] * mz
    wi = (2.0 * d * mx - wo[0], 2.0 * d * my - wo[1], 2.0 * d * mz - wo[2])
    pdf = ggx_reflection_pdf(a, wo, wi)
    if pdf <= 0.0 or wi[2] <= 0.0:
        return wi, pdf, zero
    # f cos / pdf = R F G1(wi) for separable Smith masking-shadowing
    g = ggx_g1(a, wi[0], wi[1], wi[2], mx, my, mz)
    f = _fresnel_rgb(p, d)
    return wi, pdf, (f[0] * g, f[1] * g, f[2] * g)


def check_alpha(alpha) -> float:
    value = float(alpha)
    if not (math.isfinite(value) and 1e-4 <= value <= 1.0):
        raise ParameterError(f"alpha must be in [1e-4, 1], got {alpha!r}")
    return value


class GGXConductor(BSDF):
    """Rough conductor with GGX roughness ``alpha``.  See the module docstring for the parameters."""

    kind = GGX_CONDUCTOR

    def __init__(
        self,
        alpha=0.1,
        *,
        eta=None,
        k=None,
        material: str | None = None,
        specular_reflectance=1.0,
        fresnel: bool = True,
    ):
        super().__init__()
        if material is not None and (eta is not None or k is not None):
            raise ParameterError("give either material or eta/k, not both")
        if material == "none":
            fresnel = False
            material = None
        if material is not None:
            if material not in CONDUCTOR_PRESETS:
                raise ParameterError(f"material must be one of {[*CONDUCTOR_PRESETS, 'none']}, got {material!r}")
            eta, k = CONDUCTOR_PRESETS[material]
        elif eta is None and k is None:
            eta, k = CONDUCTOR_PRESETS["Al"]
            material = "Al"
        self.alpha = check_alpha(alpha)
        self.eta = rgb_param(1.0 if eta is None else eta, "eta")
        self.k = rgb_param(0.0 if k is None else k, "k")
        if np.any(self.eta <= 0.0):
            raise ParameterError(f"eta must be > 0, got {eta!r}")
        self.material = material
        self.specular_reflectance = rgb_param(specular_reflectance, "specular_reflectance", upper=1.0)
        self.fresnel = bool(fresnel)
        self.params[_ALPHA] = self.alpha
        self.params[_ETA : _ETA + 3] = self.eta
        self.params[_K : _K + 3] = self.k
        self.params[_R : _R + 3] = self.specular_reflectance
        self.params[_FRESNEL] = 1.0 if self.fresnel else 0.0

    def __repr__(self) -> str:
        return (
            f"GGXConductor(alpha={self.alpha:g}, eta={self.eta.tolist()}, k={self.k.tolist()}, fresnel={self.fresnel})"
        )
