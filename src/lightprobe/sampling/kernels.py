"""Scalar warps for Numba kernels: one sample in, a tuple out.

Every warp is a triple, as in pbrt-v4's ``util/sampling.h``::

    square_to_X(u0, u1, ...)  -> point          # maps [0,1)^2 to the domain
    X_pdf(point..., ...)      -> density        # per unit solid angle (or area for the triangle)
    X_to_square(point..., ...) -> (u0, u1)      # the inverse of square_to_X

They take their random numbers as arguments (no hidden RNG), so they serve independent, stratified and
quasi-random samples alike and can be tested by round trip.  Directions are in the local frame of the warp
(its axis on +z).  The NumPy versions in :mod:`lightprobe.sampling.warps` call these same functions.

Everything here is ``numba.njit`` compiled; call from other kernels or, for testing, from Python.
"""

from __future__ import annotations

import math

from .._numba import jit, jit_inline

__all__ = [
    "INV_2PI",
    "INV_4PI",
    "INV_PI",
    "TWO_PI",
    "cosine_hemisphere_pdf",
    "cosine_hemisphere_to_square",
    "phi_of",
    "phong_lobe_pdf",
    "phong_lobe_to_square",
    "sincos_turns",
    "square_to_cosine_hemisphere",
    "square_to_phong_lobe",
    "square_to_uniform_cone",
    "square_to_uniform_hemisphere",
    "square_to_uniform_sphere",
    "square_to_uniform_triangle",
    "uniform_cone_pdf",
    "uniform_cone_to_square",
    "uniform_hemisphere_pdf",
    "uniform_hemisphere_to_square",
    "uniform_sphere_pdf",
    "uniform_sphere_to_square",
    "uniform_triangle_pdf",
    "uniform_triangle_to_square",
]

TWO_PI = 2.0 * math.pi
INV_PI = 1.0 / math.pi
INV_2PI = 1.0 / (2.0 * math.pi)
INV_4PI = 1.0 / (4.0 * math.pi)


@jit
def phi_of(x, y):
    """Azimuth of (x, y) in [0, 1): atan2 wrapped to the unit interval (a fraction of a full turn)."""
    f = math.atan2(y, x) * INV_2PI
    if f < 0.0:
        f += 1.0
    if f >= 1.0:  # -0.0 + 1.0 rounding
        f = 0.0
    return f


# sin x and cos x on [-pi/4, pi/4] by their Taylor series, x^15 and x^16 the last terms: the first omitted ones,
# (pi/4)^17 / 17! and (pi/4)^18 / 18!, are below 5e-17 there
_SIN_TERMS = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(8))
_COS_TERMS = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(9))


@jit_inline
def _series_tail(terms, x2):
    """terms[1] + terms[2] x2 + ... + terms[-1] x2^(n-2), by Horner's rule from the last term."""
    acc = terms[len(terms) - 1]
    for i in range(len(terms) - 2, 0, -1):
        acc = acc * x2 + terms[i]
    return acc


@jit_inline
def sincos_turns(t):
    """(sin 2 pi t, cos 2 pi t) for a finite t in turns: the nearest quarter turn q / 4 is taken out exactly, the
    rest x = 2 pi (t - q / 4) in [-pi/4, pi/4] goes through the Taylor polynomials, and q mod 4 picks the signs and
    the swap.  Within 2e-16 of the true values (libm's sin(2 pi t) is within 1e-15: its 2 pi t rounds on [0, 2 pi));
    the BSDF samples' azimuths called libm's sincos, 4 % of a render's samples (decisions.md 48)."""
    q = math.floor(4.0 * t + 0.5)
    x = TWO_PI * (t - 0.25 * q)
    x2 = x * x
    s = x + x * (_series_tail(_SIN_TERMS, x2) * x2)
    c = 1.0 + _series_tail(_COS_TERMS, x2) * x2
    # quarter turn q: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s) for q mod 4 = 0, 1, 2, 3, without branches
    # (q is random: a branch on it mispredicts)
    quadrant = int(q)
    odd = (quadrant & 1) == 1
    first = c if odd else s
    second = s if odd else c
    return float(1 - (quadrant & 2)) * first, float(1 - ((quadrant + 1) & 2)) * second


@jit
def _direction(cos_theta, sin2_theta, u_phi):
    """Unit vector with polar cosine ``cos_theta`` about +z and azimuth 2*pi*u_phi."""
    sin_theta = math.sqrt(max(0.0, sin2_theta))
    sin_phi, cos_phi = sincos_turns(u_phi)
    return sin_theta * cos_phi, sin_theta * sin_phi, cos_theta


# --- uniform sphere --------------------------------------------------------------------------------------------
@jit
def square_to_uniform_sphere(u0, u1):
    """z = 1 - 2 u1 is uniform on [-1, 1] (Archimedes), phi = 2 pi u0."""
    z = 1.0 - 2.0 * u1
    return _direction(z, (1.0 - z) * (1.0 + z), u0)


@jit
def uniform_sphere_pdf(x, y, z):
    return INV_4PI


@jit
def uniform_sphere_to_square(x, y, z):
    return phi_of(x, y), 0.5 * (1.0 - z)


# --- uniform hemisphere ----------------------------------------------------------------------------------------
@jit
def square_to_uniform_hemisphere(u0, u1):
    """z = u1 uniform on [0, 1], phi = 2 pi u0; pdf 1/(2 pi)."""
    return _direction(u1, (1.0 - u1) * (1.0 + u1), u0)


@jit
def uniform_hemisphere_pdf(x, y, z):
    return INV_2PI if z >= 0.0 else 0.0


@jit
def uniform_hemisphere_to_square(x, y, z):
    return phi_of(x, y), z


# --- cosine-weighted hemisphere (Krivanek eqs. 5-10) ----------------------------------------------------------
@jit
def square_to_cosine_hemisphere(u0, u1):
    """phi = 2 pi u0, cos(theta) = sqrt(u1) (the seed's eqs. 6-7); pdf cos(theta)/pi."""
    return _direction(math.sqrt(u1), 1.0 - u1, u0)


@jit
def cosine_hemisphere_pdf(x, y, z):
    return z * INV_PI if z > 0.0 else 0.0


@jit
def cosine_hemisphere_to_square(x, y, z):
    return phi_of(x, y), z * z


# --- Phong cosine-power lobe about +z (Krivanek eqs. 11-13) ---------------------------------------------------
@jit
def square_to_phong_lobe(u0, u1, exponent):
    """phi = 2 pi u0, cos(theta) = u1^(1/(n+1)); pdf (n+1)/(2 pi) cos^n(theta).

    sin^2(theta) is computed as -expm1(2 ln(u1)/(n+1)) so that narrow lobes (n up to 1e6) keep full precision.
    """
    if u1 <= 0.0:
        return _direction(0.0, 1.0, u0)
    log_cos = math.log(u1) / (exponent + 1.0)
    return _direction(math.exp(log_cos), -math.expm1(2.0 * log_cos), u0)


@jit
def phong_lobe_pdf(x, y, z, exponent):
    if z <= 0.0:
        return 0.0
    return (exponent + 1.0) * INV_2PI * z**exponent


@jit
def phong_lobe_to_square(x, y, z, exponent):
    if z <= 0.0:
        return phi_of(x, y), 0.0
    return phi_of(x, y), z ** (exponent + 1.0)


# --- uniform cone about +z --------------------------------------------------------------------------------------
@jit
def square_to_uniform_cone(u0, u1, cos_max):
    """cos(theta) uniform on [cos_max, 1] (u1 = 0 at the axis); pdf 1/(2 pi (1 - cos_max))."""
    one_minus_cos = u1 * (1.0 - cos_max)
    z = 1.0 - one_minus_cos
    return _direction(z, one_minus_cos * (2.0 - one_minus_cos), u0)


@jit
def uniform_cone_pdf(x, y, z, cos_max):
    if z < cos_max:
        return 0.0
    return INV_2PI / (1.0 - cos_max)


@jit
def uniform_cone_to_square(x, y, z, cos_max):
    return phi_of(x, y), (1.0 - z) / (1.0 - cos_max)


# --- uniform triangle (barycentrics) ----------------------------------------------------------------------------
@jit
def square_to_uniform_triangle(u0, u1):
    """Barycentrics (b0, b1, b2) uniform over a triangle: b0 = 1 - sqrt(u0), b1 = u1 sqrt(u0)."""
    s = math.sqrt(u0)
    b1 = u1 * s
    b2 = s - b1
    return 1.0 - s, b1, b2


@jit
def uniform_triangle_pdf(b0, b1, b2):
    """Density w.r.t. area on the reference triangle (0,0), (1,0), (0,1) spanned by (b1, b2): 1/area = 2.

    For a triangle of area A the area density is 1/A; 0 outside the triangle.
    """
    if b0 < 0.0 or b1 < 0.0 or b2 < 0.0:
        return 0.0
    return 2.0


@jit
def uniform_triangle_to_square(b0, b1, b2):
    s = 1.0 - b0
    if s <= 0.0:
        return 0.0, 0.0
    return s * s, b1 / s
