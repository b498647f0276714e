"""Area emitters (rectangles, spheres, triangles) behind one contract, and their sampling strategies.

The contract, after pbrt-v4's ``Light::SampleLi / PDF_Li / L`` and Mitsuba 3's ``sample_direction /
pdf_direction / eval``: for a reference point ``p`` with normal ``n`` and two random numbers ``u``,

* ``light_sample(...) -> (wx, wy, wz, distance, r, g, b, pdf)``: a direction toward the light, the distance to
  the sampled point (a shadow ray tests the segment, not the ray), the radiance arriving along it (zero from the
  back of a one-sided light) and the density **per steradian**; ``pdf == 0`` means "no sample" (the point is
  behind a one-sided light, or in its plane);
* ``light_pdf(...) -> pdf``: the density with which the same strategy produces direction ``w`` (0 where it never
  does); ``light_pdf_at(...)`` the same for a direction whose ray is already known to meet the light at point x
  (a BSDF sample's hit: the renderer weighs it with the density *at the point its own ray hit*, as Mitsuba 3's
  ``direct`` does, never by intersecting again from another origin);
* ``light_radiance(...)``: the radiance seen along a ray that hits the light with cosine ``cos_light`` between
  the light's normal and the reversed ray (the camera and BSDF samples use it).

Area lights are rows of the light table (:mod:`lightprobe.emitters.kinds`): rectangles, spheres and triangles (an
emissive mesh contributes one row per triangle, as pbrt-v4 does).  The renderer reaches them through the one light
contract of :mod:`lightprobe.emitters.lights`, which calls the functions here for these kinds.  Emission is uniform
RGB radiance per row; a later textured emission replaces ``radiance[l]`` by a lookup at the sampled point and
changes nothing else.

Strategies (``STRATEGIES``), each with its density per steradian:

``area``
    uniform on the light's area A; converted to solid angle (the lecture's reparameterisation,
    dw = cos(theta') dA / |x - x'|^2): p(w) = |x - x'|^2 / (|cos theta'| A).
``solid-angle``
    uniform in the solid angle the light subtends: spherical rectangles (Urena et al. 2013, as pbrt-v4's
    ``SampleSphericalRectangle``), spherical triangles (Arvo 1995, pbrt-v4's ``SampleSphericalTriangle``) and
    cones for spheres (pbrt-v4's ``Sphere::Sample``, the point built from the cone's angle, no ray traced):
    p(w) = 1 / Omega.  Fallbacks, decided from the reference
    point alone (so the sample and the pdf always agree): area sampling for a rectangle or triangle whose extent
    (a rectangle's diagonal) is at most ``SMALL_EXTENT`` = 0.25 x the distance to its centre (area sampling then
    adds at most 2.4 % relative variance to one light's unoccluded sample, a square seen from 0 to 85 degrees, where
    the spherical formulas cost 40 % of the light-sample stage of the many-light scenes: decisions.md 119; Mitsuba 3
    samples its rectangles by area everywhere), when Omega < 3e-4 sr (float round-off in the spherical formulas
    exceeds the variance they save; pbrt-v4's ``MinSphericalSampleArea``), when Omega > 6.22
    sr (the triangle nearly covers a hemisphere and Arvo's inversion loses precision; pbrt-v4's
    ``MaxSphericalSampleArea``), for a parallelogram that is not a rectangle, and for a point inside a sphere.
    For a sphere, 1 - cos(theta_max) is computed as sin^2 / (1 + cos) (no cancellation for distant spheres,
    where pbrt-v4 switches to a Taylor series in float32).
``hemisphere`` / ``cosine``
    the lecture's baseline: a direction uniform (1 / 2 pi) or cosine-weighted (cos / pi) about the reference
    normal, which counts only if it hits this light.

Every light is one-sided by default (it emits on the side its normal points to: edge_u x edge_v for
rectangles, the winding for triangles, outward for spheres); ``two_sided`` lights emit on both sides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._numba import jit, jit_inline
from .._worksharing import in_threads, read_only
from ..errors import ParameterError
from ..geometry.frame import coordinate_system, normalize, to_world
from ..geometry.intersect import (
    ANALYTIC_ERROR,
    RECT_WIDTH,
    point_error,
    rect_extent,
    rect_hit,
    rectangle_rows,
    sphere_hit,
    triangle_error,
)
from ..sampling.kernels import (
    INV_2PI,
    INV_PI,
    TWO_PI,
    square_to_cosine_hemisphere,
    square_to_uniform_hemisphere,
    square_to_uniform_triangle,
)
from .kinds import LIGHT_RECT, LIGHT_SPHERE, LIGHT_TRIANGLE, LightArrays, is_area_kind
from .kinds import LightSample as SampleRecord  # this module's LightSample is the Python API's batch

__all__ = [
    "STRATEGIES",
    "AreaLight",
    "LightSample",
    "area_power",
    "light_normal",
    "light_pdf",
    "light_pdf_at",
    "light_point_error",
    "light_radiance",
    "light_sample",
]

_AREA_KINDS = {"rectangle": LIGHT_RECT, "sphere": LIGHT_SPHERE, "triangle": LIGHT_TRIANGLE}
AREA, SOLID_ANGLE, HEMISPHERE, COSINE = 0, 1, 2, 3
STRATEGIES = {"area": AREA, "solid-angle": SOLID_ANGLE, "hemisphere": HEMISPHERE, "cosine": COSINE}
MIN_SOLID_ANGLE = 3e-4  # sr: below, spherical sampling falls back to area sampling (pbrt-v4)
MAX_SOLID_ANGLE = 6.22  # sr: above, likewise (pbrt-v4's MaxSphericalSampleArea)
# a rectangle or triangle whose extent is at most this share of its distance is sampled by area: solid-angle
# sampling would take out a few per cent of the point on the light's variance, at 2-3x the cost (decisions.md 119)
SMALL_EXTENT = 0.25


# --- geometry helpers ------------------------------------------------------------------------------------------------
@jit
def _dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@jit
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit
def _normalize3(a):
    return normalize(a[0], a[1], a[2])


@jit
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@jit
def _triangle_hit(ox, oy, oz, dx, dy, dz, g):
    """Moeller-Trumbore: t of the hit with triangle (g[0:3], g[3:6], g[6:9]), or inf."""
    e1x, e1y, e1z = g[3] - g[0], g[4] - g[1], g[5] - g[2]
    e2x, e2y, e2z = g[6] - g[0], g[7] - g[1], g[8] - g[2]
    px, py, pz = _cross(dx, dy, dz, e2x, e2y, e2z)
    det = _dot(e1x, e1y, e1z, px, py, pz)
    if det == 0.0:
        return math.inf
    inv = 1.0 / det
    sx, sy, sz = ox - g[0], oy - g[1], oz - g[2]
    b1 = _dot(sx, sy, sz, px, py, pz) * inv
    if b1 < 0.0 or b1 > 1.0:
        return math.inf
    qx, qy, qz = _cross(sx, sy, sz, e1x, e1y, e1z)
    b2 = _dot(dx, dy, dz, qx, qy, qz) * inv
    if b2 < 0.0 or b1 + b2 > 1.0:
        return math.inf
    t = _dot(e2x, e2y, e2z, qx, qy, qz) * inv
    return t if t > 0.0 else math.inf


@jit
def light_intersect(lights, l, ox, oy, oz, dx, dy, dz):
    """(t, cos_light) of the ray (o, unit d) with light l's own surface (t = inf: missed); cos_light is the cosine
    between the light's normal at the hit and -d (> 0: the front)."""
    g = lights.geom[l]
    kind = lights.kind[l]
    if not is_area_kind(kind):  # no surface: no ray meets it
        return math.inf, 0.0
    if kind == LIGHT_SPHERE:
        t = sphere_hit(ox, oy, oz, dx, dy, dz, g[0], g[1], g[2], g[3], math.inf)
        if t == math.inf:
            return t, 0.0
        nx, ny, nz = normalize(ox + t * dx - g[0], oy + t * dy - g[1], oz + t * dz - g[2])
        return t, -_dot(nx, ny, nz, dx, dy, dz)
    if kind == LIGHT_RECT:
        t = rect_hit(ox, oy, oz, dx, dy, dz, lights.geom, l, math.inf)
    else:
        t = _triangle_hit(ox, oy, oz, dx, dy, dz, g)
    return t, -_dot(g[9], g[10], g[11], dx, dy, dz)


@jit_inline
def light_normal(lights, l, x, y, z):
    """Unit normal of light l at its point (x, y, z): outward for a sphere, the row's normal for a planar light."""
    g = lights.geom[l]
    if lights.kind[l] == LIGHT_SPHERE:
        return normalize(x - g[0], y - g[1], z - g[2])
    return g[9], g[10], g[11]


@jit_inline
def light_point_error(lights, l, x, y, z, n):
    """Error bound along normal n of light l's point (x, y, z) (geometry/intersect.py): a triangle's is a mesh face's
    (Embree traces it in float32), a rectangle's and a sphere's are their float64 bounds.  A shadow ray to a sampled
    point ends this far before it, as pbrt-v4's ``SpawnRayTo`` offsets both ends."""
    g = lights.geom[l]
    kind = lights.kind[l]
    if kind == LIGHT_TRIANGLE:
        return triangle_error(g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8], n)
    extent = g[3] if kind == LIGHT_SPHERE else rect_extent(lights.geom, l)
    return point_error(ANALYTIC_ERROR, x, y, z, n[0], n[1], n[2], extent)


@jit_inline
def light_radiance(lights, l, cos_light):
    """Radiance leaving light l toward a viewer at cosine ``cos_light`` from its normal (0 behind a one-sided
    light)."""
    if cos_light > 0.0 or (cos_light < 0.0 and lights.two_sided[l] == 1):
        return lights.radiance[l, 0], lights.radiance[l, 1], lights.radiance[l, 2]
    return 0.0, 0.0, 0.0


# --- solid angles ----------------------------------------------------------------------------------------------------
@jit
def _triangle_directions(px, py, pz, g):
    """Unit vectors a, b, c from p to the triangle's vertices."""
    return (
        normalize(g[0] - px, g[1] - py, g[2] - pz),
        normalize(g[3] - px, g[4] - py, g[5] - pz),
        normalize(g[6] - px, g[7] - py, g[8] - pz),
    )


@jit
def _triangle_solid_angle(a, b, c):
    """Solid angle of the spherical triangle of unit vectors a, b, c (Van Oosterom and Strackee 1983, as pbrt-v4's
    ``SphericalTriangleArea``): 2 atan2(|a . (b x c)|, 1 + a.b + b.c + c.a).  One atan2 where Girard's theorem
    (alpha + beta + gamma - pi) takes three angles, three normalised cross products and a difference that cancels
    for small triangles; 0 for a degenerate triangle."""
    bc = _cross(b[0], b[1], b[2], c[0], c[1], c[2])
    return 2.0 * math.atan2(abs(_dot3(a, bc)), 1.0 + _dot3(a, b) + _dot3(b, c) + _dot3(c, a))


@jit
def _rect_frame(px, py, pz, g):
    """Ureña et al.'s local frame: x along edge_u, y along edge_v, z toward the side of p (so the rectangle lies
    at z0 < 0).  Returns (x axis, y axis, z axis, x0, y0, z0, |edge_u|, |edge_v|)."""
    eu = math.sqrt(_dot(g[3], g[4], g[5], g[3], g[4], g[5]))
    ev = math.sqrt(_dot(g[6], g[7], g[8], g[6], g[7], g[8]))
    xx, xy, xz = g[3] / eu, g[4] / eu, g[5] / eu
    yx, yy, yz = g[6] / ev, g[7] / ev, g[8] / ev
    zx, zy, zz = _cross(xx, xy, xz, yx, yy, yz)
    dx, dy, dz = g[0] - px, g[1] - py, g[2] - pz
    z0 = _dot(dx, dy, dz, zx, zy, zz)
    if z0 > 0.0:
        zx, zy, zz, z0 = -zx, -zy, -zz, -z0
    return (
        (xx, xy, xz),
        (yx, yy, yz),
        (zx, zy, zz),
        _dot(dx, dy, dz, xx, xy, xz),
        _dot(dx, dy, dz, yx, yy, yz),
        z0,
        eu,
        ev,
    )


@jit
def _rect_solid_angle_terms(x0, y0, z0, x1, y1):
    """Edge-plane normals' z components b0, b1 and the four internal angles g0..g3 of the spherical rectangle
    (Urena et al. 2013), in the rectangle's own frame, where the edge planes' normals have one zero
    component each: n0 ~ (0, z0, -y0), n1 ~ (-z0, 0, x1), n2 ~ (0, -z0, y1), n3 ~ (z0, 0, -x0).  The angle between
    -n_i and n_(i+1) is then atan2(|z0| |corner|, the corners' coordinate product), with |corner| the distance to the
    corner the two edges share: one square root and one atan2 an angle, accurate near 0 and pi, and no normalised
    cross products (decisions.md 91)."""
    az = abs(z0)
    z2 = z0 * z0
    g0 = math.atan2(az * math.sqrt(x1 * x1 + y0 * y0 + z2), y0 * x1)
    g1 = math.atan2(az * math.sqrt(x1 * x1 + y1 * y1 + z2), -x1 * y1)
    g2 = math.atan2(az * math.sqrt(x0 * x0 + y1 * y1 + z2), x0 * y1)
    g3 = math.atan2(az * math.sqrt(x0 * x0 + y0 * y0 + z2), -x0 * y0)
    b0 = -y0 / math.sqrt(z2 + y0 * y0)
    b1 = y1 / math.sqrt(z2 + y1 * y1)
    return b0, b1, g0, g1, g2, g3


@jit
def _is_rectangle(g):
    return abs(_dot(g[3], g[4], g[5], g[6], g[7], g[8])) <= 1e-9 * (
        _dot(g[3], g[4], g[5], g[3], g[4], g[5]) + _dot(g[6], g[7], g[8], g[6], g[7], g[8])
    )


@jit_inline
def _small_from(lights, l, px, py, pz):
    """Planar light l is small seen from p: its extent (a rectangle's diagonal; a triangle's two edges from its
    first vertex, in quadrature) at most ``SMALL_EXTENT`` x the distance to its centre."""
    g = lights.geom[l]
    ax, ay, az = g[3], g[4], g[5]
    bx, by, bz = g[6], g[7], g[8]
    if lights.kind[l] == LIGHT_RECT:
        cx, cy, cz = g[0] + 0.5 * (ax + bx), g[1] + 0.5 * (ay + by), g[2] + 0.5 * (az + bz)
    else:  # a triangle's vertices: its edges from the first, its centroid
        ax, ay, az, bx, by, bz = ax - g[0], ay - g[1], az - g[2], bx - g[0], by - g[1], bz - g[2]
        cx, cy, cz = g[0] + (ax + bx) / 3.0, g[1] + (ay + by) / 3.0, g[2] + (az + bz) / 3.0
    extent2 = ax * ax + ay * ay + az * az + bx * bx + by * by + bz * bz
    d2 = (cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2
    return extent2 <= SMALL_EXTENT * SMALL_EXTENT * d2


@jit
def _solid_angle_mode(lights, l, px, py, pz):
    """(use spherical sampling?, solid angle, sphere's cos(theta_max) or 0) for light l seen from p: the single
    place where the fallbacks of the module docstring are decided."""
    g = lights.geom[l]
    kind = lights.kind[l]
    if kind == LIGHT_SPHERE:
        d2 = (g[0] - px) ** 2 + (g[1] - py) ** 2 + (g[2] - pz) ** 2
        r2 = g[3] * g[3]
        if d2 <= r2 * (1.0 + 1e-9):
            return False, 0.0, 0.0
        sin2 = r2 / d2
        one_minus_cos = sin2 / (1.0 + math.sqrt(1.0 - sin2))  # = 1 - sqrt(1 - sin2), without cancellation
        return True, TWO_PI * one_minus_cos, 1.0 - one_minus_cos
    if _small_from(lights, l, px, py, pz):
        return False, 0.0, 0.0
    if kind == LIGHT_RECT:
        if not _is_rectangle(g):
            return False, 0.0, 0.0
        omega, _ = _rect_solid_angle(_rect_frame(px, py, pz, g))
    else:
        a, b, c = _triangle_directions(px, py, pz, g)
        omega = _triangle_solid_angle(a, b, c)
    return _spherical(omega), omega, 0.0


@jit_inline
def _spherical(omega):
    """Whether a solid angle omega is sampled spherically (else by area: the module docstring's fallbacks)."""
    return MIN_SOLID_ANGLE <= omega <= MAX_SOLID_ANGLE


@jit
def _rect_solid_angle(frame):
    """(solid angle, terms) of the rectangle in Urena et al.'s frame, the terms those of ``_rect_solid_angle_terms``
    (computed once for the solid angle and the sample); a solid angle of 0 when p lies in its plane (area sampling
    then)."""
    _, _, _, x0, y0, z0, eu, ev = frame
    if z0 == 0.0:
        return 0.0, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    terms = _rect_solid_angle_terms(x0, y0, z0, x0 + eu, y0 + ev)
    _, _, g0, g1, g2, g3 = terms
    return g0 + g1 + g2 + g3 - TWO_PI, terms


# --- the strategies --------------------------------------------------------------------------------------------------
@jit
def _sample_area_point(lights, l, px, py, pz, u0, u1):
    """A point uniform on light l's area and its outward normal."""
    g = lights.geom[l]
    kind = lights.kind[l]
    if kind == LIGHT_RECT:
        return (
            (g[0] + u0 * g[3] + u1 * g[6], g[1] + u0 * g[4] + u1 * g[7], g[2] + u0 * g[5] + u1 * g[8]),
            (g[9], g[10], g[11]),
        )
    if kind == LIGHT_TRIANGLE:
        b0, b1, b2 = square_to_uniform_triangle(u0, u1)
        return (
            (b0 * g[0] + b1 * g[3] + b2 * g[6], b0 * g[1] + b1 * g[4] + b2 * g[7], b0 * g[2] + b1 * g[5] + b2 * g[8]),
            (g[9], g[10], g[11]),
        )
    z = 1.0 - 2.0 * u0
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = TWO_PI * u1
    nx, ny, nz = r * math.cos(phi), r * math.sin(phi), z
    return (g[0] + g[3] * nx, g[1] + g[3] * ny, g[2] + g[3] * nz), (nx, ny, nz)


@jit
def _area_to_solid_angle(lights, l, distance, cos_light):
    c = abs(cos_light)
    if c == 0.0 or distance == 0.0:
        return 0.0
    return distance * distance / (c * lights.area[l])


@jit
def _sample_spherical_rect(frame, terms, px, py, pz, u0, u1):
    """Urena et al. 2013 (pbrt-v4 SampleSphericalRectangle): a point on the rectangle, uniform in solid angle;
    ``frame`` is ``_rect_frame`` of the rectangle from p and ``terms`` its ``_rect_solid_angle`` terms (computed
    once for the solid angle and the sample)."""
    ax, ay, az, x0, y0, z0, eu, ev = frame
    x1, y1 = x0 + eu, y0 + ev
    b0, b1, g0, g1, g2, g3 = terms
    au = u0 * (g0 + g1 - TWO_PI) + (u0 - 1.0) * (g2 + g3)
    fu = (math.cos(au) * b0 - b1) / math.sin(au)
    cu = math.copysign(1.0 / math.sqrt(fu * fu + b0 * b0), fu)
    cu = min(max(cu, -1.0 + 1e-12), 1.0 - 1e-12)
    xu = -(cu * z0) / math.sqrt(max(0.0, 1.0 - cu * cu))
    xu = min(max(xu, x0), x1)
    dd = math.sqrt(xu * xu + z0 * z0)
    h0 = y0 / math.sqrt(dd * dd + y0 * y0)
    h1 = y1 / math.sqrt(dd * dd + y1 * y1)
    hv = h0 + u1 * (h1 - h0)
    yv = hv * dd / math.sqrt(1.0 - hv * hv) if hv * hv < 1.0 - 1e-6 else y1
    yv = min(max(yv, y0), y1)
    xx, xy, xz = ax
    yx, yy, yz = ay
    zx, zy, zz = az
    return (
        px + xu * xx + yv * yx + z0 * zx,
        py + xu * xy + yv * yy + z0 * zy,
        pz + xu * xz + yv * yz + z0 * zz,
    )


@jit
def _sample_spherical_triangle(a, b, c, omega, u0, u1):
    """Arvo 1995 (pbrt-v4 SampleSphericalTriangle): a unit direction uniform in the solid angle omega of the
    spherical triangle of unit vectors a, b, c (``_triangle_solid_angle``, computed once for the density and the
    sample).  The angle alpha at a enters only through its cosine and sine, taken from the unit normals of the
    planes (a, b) and (c, a) as their dot and cross products: no inverse and forward trigonometry."""
    nab = _normalize3(_cross(a[0], a[1], a[2], b[0], b[1], b[2]))
    nca = _normalize3(_cross(c[0], c[1], c[2], a[0], a[1], a[2]))
    cos_alpha = -_dot3(nab, nca)  # alpha: the angle between n_ab and -n_ca
    sx, sy, sz = _cross(nab[0], nab[1], nab[2], nca[0], nca[1], nca[2])
    sin_alpha = math.sqrt(sx * sx + sy * sy + sz * sz)
    ap = math.pi + u0 * omega  # the sub-triangle's area plus pi
    sin_ap, cos_ap = math.sin(ap), math.cos(ap)
    sin_phi = sin_ap * cos_alpha - cos_ap * sin_alpha
    cos_phi = cos_ap * cos_alpha + sin_ap * sin_alpha
    k1 = cos_phi + cos_alpha
    k2 = sin_phi - sin_alpha * _dot3(a, b)
    cos_bp = (k2 + (k2 * cos_phi - k1 * sin_phi) * cos_alpha) / ((k2 * sin_phi + k1 * cos_phi) * sin_alpha)
    cos_bp = min(max(cos_bp, -1.0), 1.0)
    sin_bp = math.sqrt(max(0.0, 1.0 - cos_bp * cos_bp))
    ca = _dot3(c, a)
    gx, gy, gz = normalize(c[0] - ca * a[0], c[1] - ca * a[1], c[2] - ca * a[2])
    cpx, cpy, cpz = cos_bp * a[0] + sin_bp * gx, cos_bp * a[1] + sin_bp * gy, cos_bp * a[2] + sin_bp * gz
    cos_theta = 1.0 - u1 * (1.0 - _dot(cpx, cpy, cpz, b[0], b[1], b[2]))
    sin_theta = math.sqrt(max(0.0, 1.0 - cos_theta * cos_theta))
    cb = _dot(cpx, cpy, cpz, b[0], b[1], b[2])
    hx, hy, hz = normalize(cpx - cb * b[0], cpy - cb * b[1], cpz - cb * b[2])
    return normalize(
        cos_theta * b[0] + sin_theta * hx, cos_theta * b[1] + sin_theta * hy, cos_theta * b[2] + sin_theta * hz
    )


@jit
def _sample_sphere_cone(lights, l, px, py, pz, omega, u0, u1):
    """A direction uniform in the cone of solid angle omega that sphere light l fills seen from p (pbrt-v4
    ``Sphere::Sample(ctx, u)``): 1 - cos(theta) = u1 (1 - cos(theta_max)), phi = 2 pi u0, and the point where that
    direction first meets the sphere found from the angle alpha at the centre (cos alpha = sin^2(theta) /
    sin(theta_max) + cos(theta) sqrt(1 - sin^2(theta) / sin^2(theta_max))), so no ray is traced and a direction on
    the cone's rim still meets it.  1 - cos(theta_max) is omega / 2 pi, exact for small spheres."""
    g = lights.geom[l]
    dx, dy, dz = g[0] - px, g[1] - py, g[2] - pz
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    cx, cy, cz = dx / d, dy / d, dz / d
    sin2_max = (g[3] / d) ** 2
    one_minus_cos = u1 * (omega / TWO_PI)
    sin2 = one_minus_cos * (2.0 - one_minus_cos)
    cos_t = 1.0 - one_minus_cos
    cos_a = sin2 / math.sqrt(sin2_max) + cos_t * math.sqrt(max(0.0, 1.0 - sin2 / sin2_max))
    sin_a = math.sqrt(max(0.0, 1.0 - cos_a * cos_a))
    phi = TWO_PI * u0
    ts, tt = coordinate_system(cx, cy, cz)
    # the outward normal at the point: -(alpha, phi) about the axis from p to the centre
    nx, ny, nz = to_world(ts, tt, (cx, cy, cz), -sin_a * math.cos(phi), -sin_a * math.sin(phi), -cos_a)
    qx, qy, qz = g[0] + g[3] * nx - px, g[1] + g[3] * ny - py, g[2] + g[3] * nz - pz
    dist = math.sqrt(qx * qx + qy * qy + qz * qz)
    wx, wy, wz = qx / dist, qy / dist, qz / dist
    # the point faces p by construction (cos_light >= 0 up to round-off on the rim): the front's radiance
    r, gg, b = light_radiance(lights, l, 1.0)
    return wx, wy, wz, dist, r, gg, b, 1.0 / omega


@jit
def _toward(lights, l, px, py, pz, wx, wy, wz, pdf):
    """The sample record for direction w from p: distance and radiance where the ray meets light l."""
    t, cos_light = light_intersect(lights, l, px, py, pz, wx, wy, wz)
    if t == math.inf:  # a hemisphere sample that misses the light: a sample of the density, with no radiance
        return wx, wy, wz, math.inf, 0.0, 0.0, 0.0, pdf
    r, gg, b = light_radiance(lights, l, cos_light)
    return wx, wy, wz, t, r, gg, b, pdf


@jit
def _toward_plane(lights, l, px, py, pz, wx, wy, wz, pdf):
    """As ``_toward`` for a direction known to point into planar light l's solid angle (a spherical sample): the
    distance to its plane, with no test of its edges (round-off at an edge must not drop the sample)."""
    g = lights.geom[l]
    cos_light = -_dot(g[9], g[10], g[11], wx, wy, wz)
    t = _dot(g[0] - px, g[1] - py, g[2] - pz, g[9], g[10], g[11]) / -cos_light if cos_light != 0.0 else math.inf
    if not t > 0.0 or t == math.inf:
        return wx, wy, wz, math.inf, 0.0, 0.0, 0.0, pdf
    r, gg, b = light_radiance(lights, l, cos_light)
    return wx, wy, wz, t, r, gg, b, pdf


@jit
def _behind(lights, l, px, py, pz):
    """p cannot receive light from l: behind (or in the plane of) a one-sided planar light."""
    if lights.kind[l] == LIGHT_SPHERE or lights.two_sided[l] == 1:
        return False
    g = lights.geom[l]
    return _dot(px - g[0], py - g[1], pz - g[2], g[9], g[10], g[11]) <= 0.0


@jit
def light_sample(lights, l, strategy, px, py, pz, nx, ny, nz, u0, u1):
    """Sample a direction toward area light l from point p (normal n): (wx, wy, wz, distance, r, g, b, pdf per
    sr)."""
    if strategy == HEMISPHERE or strategy == COSINE:
        ts, tt = coordinate_system(nx, ny, nz)
        if strategy == HEMISPHERE:
            wl = square_to_uniform_hemisphere(u0, u1)
            pdf = INV_2PI
        else:
            wl = square_to_cosine_hemisphere(u0, u1)
            pdf = wl[2] * INV_PI
        wx, wy, wz = to_world(ts, tt, (nx, ny, nz), wl[0], wl[1], wl[2])
        return _toward(lights, l, px, py, pz, wx, wy, wz, pdf)
    if _behind(lights, l, px, py, pz):
        return 0.0, 0.0, 1.0, math.inf, 0.0, 0.0, 0.0, 0.0
    g = lights.geom[l]
    if strategy == SOLID_ANGLE and (lights.kind[l] == LIGHT_SPHERE or not _small_from(lights, l, px, py, pz)):
        kind = lights.kind[l]
        # the solid angle is computed once, for the choice of method, the sample and its density
        if kind == LIGHT_TRIANGLE:
            a, b, c = _triangle_directions(px, py, pz, g)
            omega = _triangle_solid_angle(a, b, c)
            if _spherical(omega):
                wx, wy, wz = _sample_spherical_triangle(a, b, c, omega, u0, u1)
                return _toward_plane(lights, l, px, py, pz, wx, wy, wz, 1.0 / omega)
        elif kind == LIGHT_RECT:
            if _is_rectangle(g):
                frame = _rect_frame(px, py, pz, g)
                omega, terms = _rect_solid_angle(frame)
                if _spherical(omega):
                    qx, qy, qz = _sample_spherical_rect(frame, terms, px, py, pz, u0, u1)
                    dx, dy, dz = qx - px, qy - py, qz - pz
                    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
                    wx, wy, wz = dx / dist, dy / dist, dz / dist
                    r, gg, b = light_radiance(lights, l, -_dot(g[9], g[10], g[11], wx, wy, wz))
                    return wx, wy, wz, dist, r, gg, b, 1.0 / omega
        else:  # a sphere: a direction uniform in the cone of directions that hit it
            spherical, omega, _ = _solid_angle_mode(lights, l, px, py, pz)
            if spherical:
                return _sample_sphere_cone(lights, l, px, py, pz, omega, u0, u1)
    # area sampling (the strategy itself, or the fallback of solid-angle sampling)
    q, nq = _sample_area_point(lights, l, px, py, pz, u0, u1)
    dx, dy, dz = q[0] - px, q[1] - py, q[2] - pz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist == 0.0:
        return 0.0, 0.0, 1.0, math.inf, 0.0, 0.0, 0.0, 0.0
    wx, wy, wz = dx / dist, dy / dist, dz / dist
    cos_light = -_dot(nq[0], nq[1], nq[2], wx, wy, wz)
    pdf = _area_to_solid_angle(lights, l, dist, cos_light)
    if pdf == 0.0:
        return wx, wy, wz, math.inf, 0.0, 0.0, 0.0, 0.0
    if lights.kind[l] == LIGHT_SPHERE:
        # a direction toward a sphere crosses it twice, and area sampling may pick either point (the far one seen
        # through the sphere): the density of the direction sums both (light_pdf), and the radiance and distance
        # are those of the first crossing, which is what a ray in direction w meets
        # (the strategy as an int64, not the literal AREA: Numba would compile light_pdf again for the literal)
        pdf = light_pdf(lights, l, np.int64(AREA), px, py, pz, nx, ny, nz, wx, wy, wz)
        return _toward(lights, l, px, py, pz, wx, wy, wz, pdf)
    r, gg, b = light_radiance(lights, l, cos_light)
    return wx, wy, wz, dist, r, gg, b, pdf


@jit
def _hemisphere_pdf(strategy, nx, ny, nz, wx, wy, wz):
    """Density of direction w under the ``hemisphere`` (1 / 2 pi) or ``cosine`` (cos / pi) strategy about n."""
    c = _dot(nx, ny, nz, wx, wy, wz)
    if c <= 0.0:
        return 0.0
    return INV_2PI if strategy == HEMISPHERE else c * INV_PI


@jit
def light_pdf(lights, l, strategy, px, py, pz, nx, ny, nz, wx, wy, wz):
    """Density per steradian with which ``light_sample(..., strategy, ...)`` produces unit direction w."""
    if not is_area_kind(lights.kind[l]):
        return 0.0
    if strategy == HEMISPHERE or strategy == COSINE:
        return _hemisphere_pdf(strategy, nx, ny, nz, wx, wy, wz)
    if _behind(lights, l, px, py, pz):
        return 0.0
    t, _ = light_intersect(lights, l, px, py, pz, wx, wy, wz)
    if t == math.inf:
        return 0.0
    return light_pdf_at(lights, l, strategy, px, py, pz, nx, ny, nz, px + t * wx, py + t * wy, pz + t * wz)


@jit
def light_pdf_at(lights, l, strategy, px, py, pz, nx, ny, nz, x, y, z):
    """Density per steradian with which ``light_sample(..., strategy, ...)`` from p produces the direction toward
    point (x, y, z) of light l, a point a ray is known to have hit: the density of *that* point, with no second
    intersection (a BSDF ray leaves an offset origin, and from p itself its twin may miss a small light's edge;
    weighing it with a density of 0 there counted that band twice under MIS)."""
    if not is_area_kind(lights.kind[l]):
        return 0.0
    dx, dy, dz = x - px, y - py, z - pz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist == 0.0:
        return 0.0
    wx, wy, wz = dx / dist, dy / dist, dz / dist
    if strategy == HEMISPHERE or strategy == COSINE:
        return _hemisphere_pdf(strategy, nx, ny, nz, wx, wy, wz)
    if _behind(lights, l, px, py, pz):
        return 0.0
    if strategy == SOLID_ANGLE:
        spherical, omega, _ = _solid_angle_mode(lights, l, px, py, pz)
        if spherical:
            return 1.0 / omega
    ln = light_normal(lights, l, x, y, z)
    cos_light = -_dot(ln[0], ln[1], ln[2], wx, wy, wz)
    pdf = _area_to_solid_angle(lights, l, dist, cos_light)
    if lights.kind[l] == LIGHT_SPHERE:
        # the ray crosses the sphere twice; area sampling can pick either point (the far one seen through the
        # sphere), so the density of the direction is the sum over both crossings
        g = lights.geom[l]
        # second crossing: along the chord, t2 = t + 2 (c - x) . w with c the centre
        t2 = dist + 2.0 * _dot(g[0] - x, g[1] - y, g[2] - z, wx, wy, wz)
        if t2 > dist:
            pdf += _area_to_solid_angle(lights, l, t2, cos_light)
    return pdf


# --- batch kernels and the Python interface -----------------------------------------------------------------------
# Range kernels run by threads (``_worksharing.in_threads``), not ``prange`` loops: the same values (each row is its
# own), and Numba's parallel-loop passes made them slow to compile (decisions.md 129).
@jit
def _sample_range(lights, l, strategy, points, normals, u, out, lo, hi):
    for i in range(lo, hi):
        rec = light_sample(
            lights,
            l,
            strategy,
            points[i, 0],
            points[i, 1],
            points[i, 2],
            normals[i, 0],
            normals[i, 1],
            normals[i, 2],
            u[i, 0],
            u[i, 1],
        )
        for j in range(8):
            out[i, j] = rec[j]


def _sample_batch(lights, l, strategy, points, normals, u):
    out = np.empty((u.shape[0], 8))
    in_threads(_sample_range, u.shape[0], lights, l, strategy, points, normals, u, out)
    return out


@jit
def _pdf_range(lights, l, strategy, points, normals, dirs, out, lo, hi):
    for i in range(lo, hi):
        out[i] = light_pdf(
            lights,
            l,
            strategy,
            points[i, 0],
            points[i, 1],
            points[i, 2],
            normals[i, 0],
            normals[i, 1],
            normals[i, 2],
            dirs[i, 0],
            dirs[i, 1],
            dirs[i, 2],
        )


def _pdf_batch(lights, l, strategy, points, normals, dirs):
    out = np.empty(dirs.shape[0])
    in_threads(_pdf_range, dirs.shape[0], lights, l, strategy, points, normals, dirs, out)
    return out


@jit
def _eval_range(lights, l, points, dirs, out, lo, hi):
    for i in range(lo, hi):
        t, c = light_intersect(lights, l, points[i, 0], points[i, 1], points[i, 2], dirs[i, 0], dirs[i, 1], dirs[i, 2])
        if t < math.inf:
            out[i, 0], out[i, 1], out[i, 2] = light_radiance(lights, l, c)


def _eval_batch(lights, l, points, dirs):
    out = np.zeros((dirs.shape[0], 3))
    in_threads(_eval_range, dirs.shape[0], lights, l, points, dirs, out)
    return out


@dataclass(frozen=True)
class LightSample:
    """What :meth:`AreaLight.sample_li` returns, per sample: unit direction toward the light (N, 3), distance to
    the sampled point (N,), radiance arriving along it (N, 3), density per steradian (N,; 0 = no sample), and
    whether the light is a delta light (never, for area lights)."""

    direction: np.ndarray
    distance: np.ndarray
    radiance: np.ndarray
    pdf: np.ndarray
    delta: bool = False


def _rgb(value, name: str) -> np.ndarray:
    from ..bsdfs.base import rgb_param

    return rgb_param(value, name)


def _rows(points, name: str, n: int | None = None) -> np.ndarray:
    a = np.asarray(points, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ParameterError(f"{name} must be (N, 3) or (3,), got shape {a.shape}")
    if n is not None and a.shape[0] == 1 and n > 1:
        a = np.repeat(a, n, axis=0)
    return read_only(np.ascontiguousarray(a))  # one signature of the batch kernels


class AreaLight:
    """One area emitter with uniform radiance, testable outside the renderer.

    ``AreaLight.rectangle(origin, edge_u, edge_v, radiance)``, ``AreaLight.sphere(center, radius, radiance)``,
    ``AreaLight.triangle(v0, v1, v2, radiance)``; ``two_sided=True`` emits on both sides.  ``strategy`` is one of
    :data:`STRATEGIES`.
    """

    def __init__(self, kind: str, geom, radiance, *, two_sided: bool = False):
        if kind not in _AREA_KINDS:
            raise ParameterError(f"light kind must be one of {list(_AREA_KINDS)}, got {kind!r}")
        self.kind = kind
        self.geom = _geom_row(kind, geom)
        self.radiance = _rgb(radiance, "emission")
        self.two_sided = bool(two_sided)
        self.area = _area(kind, self.geom)
        self._arrays = LightArrays(
            np.array([_AREA_KINDS[kind]], np.int64),
            self.geom.reshape(1, RECT_WIDTH).copy(),
            self.radiance.reshape(1, 3).copy(),
            np.array([int(self.two_sided)], np.int64),
            np.array([self.area]),
        )

    @classmethod
    def rectangle(cls, origin, edge_u, edge_v, radiance, *, two_sided: bool = False) -> AreaLight:
        from ..geometry.shapes import Rectangle

        r = Rectangle(origin, edge_u, edge_v)
        return cls("rectangle", [*r.origin, *r.edge_u, *r.edge_v], radiance, two_sided=two_sided)

    @classmethod
    def sphere(cls, center, radius, radiance, *, two_sided: bool = False) -> AreaLight:
        from ..geometry.shapes import Sphere

        s = Sphere(center, radius)
        return cls("sphere", [*s.center, s.radius], radiance, two_sided=two_sided)

    @classmethod
    def triangle(cls, v0, v1, v2, radiance, *, two_sided: bool = False) -> AreaLight:
        v = np.array([v0, v1, v2], dtype=np.float64)
        n = np.cross(v[1] - v[0], v[2] - v[0])
        if v.shape != (3, 3) or not np.all(np.isfinite(v)) or not np.linalg.norm(n) > 0:
            raise ParameterError("a triangle light needs three finite, non-collinear vertices")
        return cls("triangle", [*v.reshape(-1), *(n / np.linalg.norm(n))], radiance, two_sided=two_sided)

    @property
    def power(self) -> float:
        """Emitted flux of the luminance: pi A L (x 2 if two-sided)."""
        return float(area_power(self._arrays)[0])

    def _strategy(self, strategy: str) -> int:
        if strategy not in STRATEGIES:
            raise ParameterError(f"light strategy must be one of {list(STRATEGIES)}, got {strategy!r}")
        return STRATEGIES[strategy]

    def sample_li(self, points, normals, u, *, strategy: str = "solid-angle") -> LightSample:
        """Sample directions toward the light from ``points`` (N, 3) with ``normals`` (N, 3); ``u`` (N, 2)."""
        uu = np.ascontiguousarray(np.asarray(u, dtype=np.float64).reshape(-1, 2))
        n = uu.shape[0]
        out = _sample_batch(
            self._arrays, 0, self._strategy(strategy), _rows(points, "points", n), _rows(normals, "normals", n), uu
        )
        return LightSample(out[:, :3], out[:, 3], out[:, 4:7], out[:, 7])

    def pdf_li(self, points, normals, dirs, *, strategy: str = "solid-angle") -> np.ndarray:
        d = _rows(dirs, "dirs")
        n = d.shape[0]
        return _pdf_batch(
            self._arrays, 0, self._strategy(strategy), _rows(points, "points", n), _rows(normals, "normals", n), d
        )

    def eval(self, points, dirs) -> np.ndarray:
        """Radiance (N, 3) seen from ``points`` along ``dirs`` (zero where the ray misses the light or meets its
        back)."""
        d = _rows(dirs, "dirs")
        return _eval_batch(self._arrays, 0, _rows(points, "points", d.shape[0]), d)

    def __repr__(self) -> str:
        return f"AreaLight({self.kind!r}, radiance={self.radiance.tolist()}, two_sided={self.two_sided})"


def _geom_row(kind: str, geom) -> np.ndarray:
    """A light table row (RECT_WIDTH,) from a rectangle's corner and edges (9 numbers), a sphere's centre and radius
    (4) or a triangle's vertices and unit normal (12); the rest 0."""
    g = np.asarray(geom, dtype=np.float64).reshape(-1)
    if kind == "rectangle":
        return rectangle_rows(g[0:3], g[3:6], g[6:9])[0]
    row = np.zeros(RECT_WIDTH)
    row[: g.size] = g
    return row


def _area(kind: str, g: np.ndarray) -> float:
    if kind == "rectangle":
        return float(np.linalg.norm(np.cross(g[3:6], g[6:9])))
    if kind == "triangle":
        return float(0.5 * np.linalg.norm(np.cross(g[3:6] - g[0:3], g[6:9] - g[0:3])))
    return float(4.0 * math.pi * g[3] ** 2)


def area_power(lights: LightArrays) -> np.ndarray:
    """Emitted power (of the luminance) of each row: pi A L, doubled for two-sided lights."""
    from ..color import luminance

    return math.pi * lights.area * luminance(lights.radiance) * np.where(lights.two_sided == 1, 2.0, 1.0)


# --- the light contract (lights.py's dispatchers call these, generated from kinds.KINDS) ------------------------------
# Every kind's module has the same three functions, inlined into the dispatchers; each calls the kind's own sampler
# with only its own data (a call taking the environment's record cost a light sample 30-70 ns: decisions.md 91).
@jit_inline
def row_sample(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, u0, u1):
    """Area light l's :class:`~.kinds.LightSample` from p (normal n): :func:`light_sample`."""
    wx, wy, wz, dist, r, g, b, pdf = light_sample(lights, l, strategy, px, py, pz, nx, ny, nz, u0, u1)
    return SampleRecord(wx, wy, wz, dist, r, g, b, pdf, False)


@jit_inline
def row_pdf(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, wx, wy, wz):
    """Area light l's density per steradian of direction w from p: :func:`light_pdf`."""
    return light_pdf(lights, l, strategy, px, py, pz, nx, ny, nz, wx, wy, wz)
