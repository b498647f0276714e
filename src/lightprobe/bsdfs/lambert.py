"""Lambertian (ideal diffuse) reflection: f = albedo / pi.

Parameters
----------
albedo : float or RGB
    Diffuse reflectance in [0, 1].

Sampling is cosine-weighted (pdf cos(theta_i)/pi), so the sample weight is exactly the albedo.
"""

from __future__ import annotations

from .._numba import jit_inline
from ..sampling.kernels import INV_PI, cosine_hemisphere_pdf, square_to_cosine_hemisphere
from .base import BSDF, rgb_param

__all__ = ["LAMBERT", "Lambert"]

LAMBERT = 0


@jit_inline
def lambert_eval(p, wo, wi):
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0, 0.0, 0.0
    return p[0] * INV_PI, p[1] * INV_PI, p[2] * INV_PI


@jit_inline
def lambert_pdf(p, wo, wi):
    if wo[2] <= 0.0:
        return 0.0
    return cosine_hemisphere_pdf(wi[0], wi[1], wi[2])


@jit_inline
def lambert_sample(p, wo, u0, u1, u2):
    """Returns (wi, pdf, weight) with weight = f cos / pdf = albedo."""
    if wo[2] <= 0.0:
        return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0)
    wi = square_to_cosine_hemisphere(u1, u2)
    pdf = cosine_hemisphere_pdf(wi[0], wi[1], wi[2])
    if pdf <= 0.0:  # u2 == 0 gives a horizon direction
        return wi, 0.0, (0.0, 0.0, 0.0)
    return wi, pdf, (p[0], p[1], p[2])


@jit_inline
def lambert_textured(out, r, g, b):
    """The block ``out`` (a copy of the material's) at a texel of base colour (r, g, b): the albedo times it."""
    out[0] *= r
    out[1] *= g
    out[2] *= b


class Lambert(BSDF):
    """Ideal diffuse reflector with reflectance ``albedo`` (scalar or RGB in [0, 1]); ``textures``: a
    :class:`~lightprobe.textures.MaterialTextures` whose ``base_color`` multiplies the albedo (and ``normal``)."""

    kind = LAMBERT
    texture_uses = ("base_color", "normal")

    def __init__(self, albedo=0.5, *, textures=None):
        super().__init__()
        self.albedo = rgb_param(albedo, "albedo", upper=1.0)
        self.params[0:3] = self.albedo
        self.textures = self.check_textures(textures)

    def __repr__(self) -> str:
        return f"Lambert(albedo={self.albedo.tolist()})"
