"""The glTF 2.0 metallic-roughness material, as the specification's appendix B defines it.

::

    f = mix(dielectric, metal, metallic)
    metal      = F_metal(V.H) V(wo, wi) D(h),          F_metal = c + (1 - c) (1 - |V.H|)^5
    dielectric = mix(c / pi, V(wo, wi) D(h), F_d(V.H)),  F_d = 0.04 + 0.96 (1 - |V.H|)^5

with c the base colour, h the half vector, D the GGX distribution of alpha = roughness^2 and V the height-correlated
Smith visibility term (the glTF sample renderer's V_GGX, G2 / (4 |N.L| |N.V|))::

    V = 0.5 / (N.L sqrt((N.V)^2 (1 - alpha^2) + alpha^2) + N.V sqrt((N.L)^2 (1 - alpha^2) + alpha^2))

Schlick's Fresnel from F0 = 0.04 (dielectrics, ior 1.5) or F0 = c (metals) weighs the specular layer, and the
diffuse base by what the layer does not reflect. The model is the specification's, not an energy-conserving one:
its white furnace stays at or below 1 (a test), losing the energy the single-scattering GGX lobe loses at high
roughness.

Sampling: the specular lobe by GGX visible normals (Heitz 2018, as the conductor), the diffuse lobe by the cosine;
the lobe is chosen with the probability of an estimate of its weight at wo, from Schlick's Fresnel at N.V,
P_s = ((1 - m) F_d + m F_metal) / ((1 - m) F_d + m F_metal + (1 - m)(1 - F_d) mean(c)), by the pair's second
number, rescaled (``bsdfs/base.py``). The pdf is the mixture. ``roughness`` below 0.01 acts as 0.01 (alpha 1e-4,
the conductor's floor).
"""

from __future__ import annotations

import math

from .._numba import jit, jit_inline
from ..errors import ParameterError
from ..sampling.distributions import choose_rescaled
from ..sampling.kernels import INV_PI, cosine_hemisphere_pdf
from .base import BSDF, rgb_param
from .conductor import ggx_reflection_pdf
from .microfacet import ggx_d_terms, specular_or_diffuse_direction

__all__ = ["METALLIC_ROUGHNESS", "MetallicRoughness"]

METALLIC_ROUGHNESS = 4
DIELECTRIC_F0 = 0.04
ALPHA_MIN = 1e-4
# parameter block: base colour[0:3], metallic[3], alpha[4], mean base colour[5], roughness[6] (for textures)
_METALLIC, _ALPHA, _MEAN, _ROUGHNESS = 3, 4, 5, 6


@jit
def _schlick_weight(cos_theta):
    """(1 - |cos|)^5."""
    x = 1.0 - min(abs(cos_theta), 1.0)
    x2 = x * x
    return x2 * x2 * x


@jit_inline
def _specular_vd(alpha, wo, wi):
    """(V D, V.H) of the GGX layer for wo, wi above the surface; (0, 0) where the half vector faces away."""
    hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
    n2 = hx * hx + hy * hy + hz * hz
    if hz <= 0.0 or n2 <= 0.0:
        return 0.0, 0.0
    num, e2 = ggx_d_terms(alpha, hx, hy, hz)
    d = num / (math.pi * e2)
    a2 = alpha * alpha
    nl, nv = wi[2], wo[2]
    denom = nl * math.sqrt(nv * nv * (1.0 - a2) + a2) + nv * math.sqrt(nl * nl * (1.0 - a2) + a2)
    if denom <= 0.0:
        return 0.0, 0.0
    v_dot_h = (wo[0] * hx + wo[1] * hy + wo[2] * hz) / math.sqrt(n2)
    return 0.5 / denom * d, v_dot_h


@jit_inline
def metallic_roughness_eval(p, wo, wi):
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0, 0.0, 0.0
    spec, v_dot_h = _specular_vd(p[_ALPHA], wo, wi)
    s = _schlick_weight(v_dot_h)
    m = p[_METALLIC]
    f_d = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * s
    out0 = (1.0 - m) * ((1.0 - f_d) * p[0] * INV_PI + f_d * spec) + m * (p[0] + (1.0 - p[0]) * s) * spec
    out1 = (1.0 - m) * ((1.0 - f_d) * p[1] * INV_PI + f_d * spec) + m * (p[1] + (1.0 - p[1]) * s) * spec
    out2 = (1.0 - m) * ((1.0 - f_d) * p[2] * INV_PI + f_d * spec) + m * (p[2] + (1.0 - p[2]) * s) * spec
    return out0, out1, out2


@jit
def _specular_probability(p, wo):
    s = _schlick_weight(wo[2])
    m, c = p[_METALLIC], p[_MEAN]
    f_d = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * s
    ws = (1.0 - m) * f_d + m * (c + (1.0 - c) * s)
    wd = (1.0 - m) * (1.0 - f_d) * c
    return ws / (ws + wd) if ws + wd > 0.0 else 1.0


@jit_inline
def metallic_roughness_pdf(p, wo, wi):
    if wo[2] <= 0.0:
        return 0.0
    ps = _specular_probability(p, wo)
    return ps * ggx_reflection_pdf(p[_ALPHA], wo, wi) + (1.0 - ps) * cosine_hemisphere_pdf(wi[0], wi[1], wi[2])


# a function of its own, not inlined: the setup stage that calls it compiles 4 s sooner (decisions.md 112)
@jit
def metallic_roughness_sample(p, wo, u0, u1, u2):
    zero = (0.0, 0.0, 0.0)
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, zero
    specular, v = choose_rescaled(u2, _specular_probability(p, wo))
    wi = specular_or_diffuse_direction(p[_ALPHA], wo, specular, u1, v)
    pdf = metallic_roughness_pdf(p, wo, wi)
    if pdf <= 0.0 or wi[2] <= 0.0:
        return wi, pdf, zero
    f = metallic_roughness_eval(p, wo, wi)
    k = wi[2] / pdf
    return wi, pdf, (f[0] * k, f[1] * k, f[2] * k)


@jit_inline
def metallic_roughness_textured(p, out, r, g, b, metallic, roughness):
    """The block ``out`` (a copy of ``p``) at a texel: base colour x (r, g, b), metallic x ``metallic``, roughness x
    ``roughness``, and what follows from them, computed as the constructor does (a white texel changes nothing)."""
    out[0], out[1], out[2] = p[0] * r, p[1] * g, p[2] * b
    out[_METALLIC] = p[_METALLIC] * metallic
    rough = p[_ROUGHNESS] * roughness
    out[_ALPHA] = max(rough * rough, ALPHA_MIN)
    out[_MEAN] = (out[0] + out[1] + out[2]) / 3.0
    out[_ROUGHNESS] = rough


def _unit(value, name: str) -> float:
    x = float(value)
    if not (math.isfinite(x) and 0.0 <= x <= 1.0):
        raise ParameterError(f"{name} must be in [0, 1], got {value!r}")
    return x


class MetallicRoughness(BSDF):
    """glTF 2.0's metallic-roughness material (``baseColorFactor``, ``metallicFactor``, ``roughnessFactor``).
    See the module docstring."""

    kind = METALLIC_ROUGHNESS
    texture_uses = ("base_color", "metallic_roughness", "normal")

    def __init__(self, base_color=1.0, metallic=1.0, roughness=1.0, *, textures=None):
        super().__init__()  # the defaults are the specification's
        self.base_color = rgb_param(base_color, "base_color", upper=1.0)
        self.metallic = _unit(metallic, "metallic")
        self.roughness = _unit(roughness, "roughness")
        self.alpha = max(self.roughness * self.roughness, ALPHA_MIN)
        self.params[0:3] = self.base_color
        self.params[_METALLIC] = self.metallic
        self.params[_ALPHA] = self.alpha
        self.params[_MEAN] = float(self.base_color.mean())
        self.params[_ROUGHNESS] = self.roughness
        self.textures = self.check_textures(textures)

    def __repr__(self) -> str:
        return (
            f"MetallicRoughness(base_color={self.base_color.tolist()}, metallic={self.metallic:g}, "
            f"roughness={self.roughness:g})"
        )
