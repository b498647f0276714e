"""Exact unpolarised Fresnel reflectance (not Schlick's approximation), as pbrt-v4's ``FrDielectric``/``FrComplex``.

``eta`` is the index of the material relative to the outside medium; ``k`` the extinction coefficient of a
conductor.  cos_theta_i is measured on the side the light arrives from.  Both are inlined into their callers
(``jit_inline``): ``perf`` found the dielectric's as a real call in the setup stage, its arguments spilled per sample.
"""

from __future__ import annotations

import math

from .._numba import jit_inline

__all__ = ["fresnel_conductor", "fresnel_dielectric"]


@jit_inline
def fresnel_dielectric(cos_theta_i, eta):
    """Reflectance of a dielectric interface; light arriving from inside (cos < 0) sees 1/eta."""
    c = min(max(cos_theta_i, -1.0), 1.0)
    if c < 0.0:
        eta = 1.0 / eta
        c = -c
    sin2_t = (1.0 - c * c) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0  # total internal reflection
    cos_t = math.sqrt(1.0 - sin2_t)
    # 0.5 (r_parl^2 + r_perp^2) with r_parl = a / b, r_perp = g / h over one division
    a, b = eta * c - cos_t, eta * c + cos_t
    g, h = c - eta * cos_t, c + eta * cos_t
    return 0.5 * (a * a * h * h + g * g * b * b) / (b * b * h * h)


@jit_inline
def fresnel_conductor(cos_theta_i, eta, k):
    """Reflectance of a conductor with complex index eta + i k (exact; real-arithmetic form of pbrt-v3's
    ``FrConductor``, about 3x cheaper than complex square roots)."""
    c = min(max(cos_theta_i, 0.0), 1.0)
    cos2 = c * c
    sin2 = 1.0 - cos2
    eta2 = eta * eta
    k2 = k * k
    t0 = eta2 - k2 - sin2
    a2_plus_b2 = math.sqrt(t0 * t0 + 4.0 * eta2 * k2)
    t1 = a2_plus_b2 + cos2
    a = math.sqrt(max(0.0, 0.5 * (a2_plus_b2 + t0)))
    t2 = 2.0 * c * a
    t3 = cos2 * a2_plus_b2 + sin2 * sin2
    t4 = t2 * sin2
    # rs = (t1 - t2) / (t1 + t2), rp = rs (t3 - t4) / (t3 + t4), and 0.5 (rs + rp) = rs t3 / (t3 + t4): one division
    return (t1 - t2) * t3 / ((t1 + t2) * (t3 + t4))
