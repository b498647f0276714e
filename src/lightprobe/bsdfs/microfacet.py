"""The isotropic GGX (Trowbridge-Reitz) microfacet distribution, with visible-normal sampling.

``alpha`` is the roughness parameter itself (not squared, not "perceptual").  In the local frame (normal +z)::

    D(m)     = alpha^2 / (pi (cos^2(theta_m) (alpha^2 - 1) + 1)^2)
    G1(v, m) = 2 / (1 + sqrt(1 + alpha^2 tan^2(theta_v)))   if dot(v, m) cos(theta_v) > 0, else 0
    D_v(m)   = G1(v, m) max(0, dot(v, m)) D(m) / cos(theta_v)       (distribution of visible normals)

Visible normals are sampled with Heitz 2018, "Sampling the GGX Distribution of Visible Normals" (JCGT 7(4)).
"""

from __future__ import annotations

import math

from .._numba import jit, jit_inline
from ..sampling.kernels import sincos_turns, square_to_cosine_hemisphere

__all__ = [
    "ggx_d",
    "ggx_d_terms",
    "ggx_g1",
    "ggx_g1_denominator",
    "ggx_sample_visible_normal",
    "specular_or_diffuse_direction",
]


@jit
def ggx_d(alpha, mx, my, mz):
    """D of a unit microfacet normal m. With mx^2 + my^2 = 1 - mz^2 the denominator's cos^2 (alpha^2 - 1) + 1 is
    mx^2 + my^2 + alpha^2 mz^2 (:func:`ggx_d_terms`'s form)."""
    if mz <= 0.0:
        return 0.0
    a2 = alpha * alpha
    c2 = mz * mz
    denom = c2 * (a2 - 1.0) + 1.0
    return a2 / (math.pi * denom * denom)


@jit
def ggx_d_terms(alpha, hx, hy, hz):
    """(alpha^2 |h|^4, e^2) with D(h / |h|) = alpha^2 |h|^4 / (pi e^2) for an unnormalized half vector h (hz > 0),
    e = hx^2 + hy^2 + alpha^2 hz^2: D without normalizing h, so that a caller folds pi e^2 into its one division
    (a division or square root costs 5-8 cycles of the one divider; decisions.md 62)."""
    a2 = alpha * alpha
    n2 = hx * hx + hy * hy + hz * hz
    e = hx * hx + hy * hy + a2 * hz * hz
    return a2 * n2 * n2, e * e


@jit
def ggx_g1_denominator(alpha, c):
    """c + sqrt(c^2 + alpha^2 (1 - c^2)) for a direction's cosine c > 0 (2 c where c >= 1), so that G1 = 2 c / this:
    2 / (1 + sqrt(1 + alpha^2 tan^2)) without tan^2's division; callers fold it into their one division."""
    if c >= 1.0:
        return 2.0 * c
    return c + math.sqrt(c * c + alpha * alpha * (1.0 - c * c))


@jit
def ggx_g1(alpha, vx, vy, vz, mx, my, mz):
    """Smith masking of direction v for microfacet normal m (the separable form is G1(wi) G1(wo)):
    2 |vz| / ggx_g1_denominator(alpha, |vz|)."""
    if (vx * mx + vy * my + vz * mz) * vz <= 0.0:
        return 0.0
    c = abs(vz)
    return 2.0 * c / ggx_g1_denominator(alpha, c)


@jit_inline
def ggx_sample_visible_normal(alpha, vx, vy, vz, u1, u2):
    """A microfacet normal visible from v (v.z > 0), distributed as D_v (Heitz 2018, listing 1)."""
    # stretch the view direction to the hemisphere configuration
    hx, hy, hz = alpha * vx, alpha * vy, vz
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    lensq = hx * hx + hy * hy
    if lensq > 0.0:
        il = 1.0 / math.sqrt(lensq)
        t1x, t1y, t1z = -hy * il, hx * il, 0.0
    else:
        t1x, t1y, t1z = 1.0, 0.0, 0.0
    # t2 = cross(h, t1)
    t2x = hy * t1z - hz * t1y
    t2y = hz * t1x - hx * t1z
    t2z = hx * t1y - hy * t1x
    # uniform point on the disc, warped to the projected visible hemisphere
    r = math.sqrt(u1)
    sin_phi, cos_phi = sincos_turns(u2)
    p1 = r * cos_phi
    p2 = r * sin_phi
    s = 0.5 * (1.0 + hz)
    p2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    nx = p1 * t1x + p2 * t2x + p3 * hx
    ny = p1 * t1y + p2 * t2y + p3 * hy
    nz = p1 * t1z + p2 * t2z + p3 * hz
    # unstretch
    mx, my, mz = alpha * nx, alpha * ny, max(1e-12, nz)
    inv = 1.0 / math.sqrt(mx * mx + my * my + mz * mz)
    return mx * inv, my * inv, mz * inv


@jit_inline
def specular_or_diffuse_direction(alpha, wo, specular, u1, v):
    """The direction of a sample of a material with a GGX layer over a diffuse base (the rough plastic, glTF's
    metallic-roughness): wo reflected about a visible normal (``specular``) or a cosine-weighted direction, from
    the pair (u1, v) whose second number the lobe choice rescaled."""
    if specular:
        mx, my, mz = ggx_sample_visible_normal(alpha, wo[0], wo[1], wo[2], u1, v)
        d = wo[0] * mx + wo[1] * my + wo[2] * mz
        return 2.0 * d * mx - wo[0], 2.0 * d * my - wo[1], 2.0 * d * mz - wo[2]
    return square_to_cosine_hemisphere(u1, v)
