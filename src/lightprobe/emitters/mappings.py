"""Image <-> direction mappings of environment maps, in the environment's own frame (Y up, right-handed).

Latitude-longitude (equirectangular), identical to Mitsuba 3's ``envmap``::

    u = atan2(x, -z) / (2 pi)  (wrapped to [0, 1)),   v = acos(y) / pi
    theta = pi v, phi = 2 pi u,  d = (sin(phi) sin(theta), cos(theta), -cos(phi) sin(theta))

Row 0 (v = 0) is the zenith +Y, the last row the nadir; u = 0 is -Z, u = 0.25 is +X, u = 0.5 is +Z.

Debevec's angular map ("light probe" images, the seed's section 3.2; Radiance's ``angmap.cal``): the image centre
looks along +Z, the rim of the disc is -Z, +Y is up and +X to the right; the distance from the centre is
proportional to the angle from +Z::

    r = acos(z) / (2 pi sqrt(x^2 + y^2)),   s = 0.5 + x r  (column, from the left),   t = 0.5 - y r  (row, from top)

Pixels outside the unit disc are not directions.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_parallel, prange
from ..sampling.kernels import INV_2PI, INV_PI, TWO_PI

__all__ = [
    "angular_to_direction",
    "direction_to_angular",
    "direction_to_latlong",
    "latlong_to_direction",
]


@jit
def direction_to_latlong(x, y, z):
    """(u, v) in [0, 1) x [0, 1] of an env-frame unit direction (Mitsuba's convention)."""
    u = math.atan2(x, -z) * INV_2PI
    if u < 0.0:
        u += 1.0
    if u >= 1.0:
        u = 0.0
    v = math.acos(min(1.0, max(-1.0, y))) * INV_PI
    return u, v


@jit
def latlong_to_direction(u, v):
    theta = math.pi * v
    phi = TWO_PI * u
    st = math.sin(theta)
    return math.sin(phi) * st, math.cos(theta), -math.cos(phi) * st


@jit
def direction_to_angular(x, y, z):
    """(s, t): column and row coordinates in [0, 1] of the angular map (row 0 at the top)."""
    d = math.sqrt(x * x + y * y)
    r = INV_2PI * math.acos(min(1.0, max(-1.0, z))) / d if d > 0.0 else 0.0
    return 0.5 + x * r, 0.5 - y * r


@jit
def angular_to_direction(s, t):
    """Direction of angular-map coordinates (s, t); returns (x, y, z, inside) with inside False off the disc."""
    a = 2.0 * s - 1.0
    b = 1.0 - 2.0 * t
    rho = math.sqrt(a * a + b * b)
    if rho > 1.0:
        return 0.0, 0.0, -1.0, False
    if rho == 0.0:
        return 0.0, 0.0, 1.0, True
    theta = math.pi * rho
    k = math.sin(theta) / rho
    return a * k, b * k, math.cos(theta), True


@jit
def _bilerp(image, y0, y1, x0, x1, ty, tx, c):
    top = (1.0 - tx) * image[y0, x0, c] + tx * image[y0, x1, c]
    bottom = (1.0 - tx) * image[y1, x0, c] + tx * image[y1, x1, c]
    return (1.0 - ty) * top + ty * bottom


@jit
def bilinear_latlong_weights(h, w, u, v):
    """Texels and weights of a bilinear lookup at (u, v) with Mitsuba's texel placement.

    Column i sits at u = (i + 0.5) / W (periodic in u); row j at v = j / (H - 1), so row 0 is exactly the zenith
    and the last row exactly the nadir (corner-aligned in v, clamped).  Returns (y0, y1, x0, x1, ty, tx).
    """
    fx = u * w - 0.5
    x0f = math.floor(fx)
    tx = fx - x0f
    # wrap with compares, not Python's modulo (an integer division: two of them took 29 of the 128 core-ns of a
    # BSDF direction's environment lookup, decisions.md 33); lat-long u in [0, 1) needs at most one step either way
    x0 = int(x0f)
    if x0 < 0:
        x0 += w
    elif x0 >= w:
        x0 -= w
    if x0 < 0 or x0 >= w:
        x0 %= w
    x1 = x0 + 1 if x0 + 1 < w else 0
    if h > 1:
        fy = min(max(v, 0.0), 1.0) * (h - 1)
        y0 = min(int(fy), h - 2)
        ty = fy - y0
    else:
        y0 = 0
        ty = 0.0
    return y0, min(y0 + 1, h - 1), x0, x1, ty, tx


@jit
def bilinear_latlong(image, u, v):
    """Bilinear RGB lookup in a lat-long image (:func:`bilinear_latlong_weights`)."""
    y0, y1, x0, x1, ty, tx = bilinear_latlong_weights(image.shape[0], image.shape[1], u, v)
    return (
        _bilerp(image, y0, y1, x0, x1, ty, tx, 0),
        _bilerp(image, y0, y1, x0, x1, ty, tx, 1),
        _bilerp(image, y0, y1, x0, x1, ty, tx, 2),
    )


@jit_parallel
def bilinear_cell_means(values, f, k):
    """Mean of the bilinear reconstruction of a single-channel lat-long image (H, W) over each cell of a grid f
    times finer (H f, W f), from k x k evenly spaced points per cell."""
    h, w = values.shape
    rows, cols = h * f, w * f
    out = np.empty((rows, cols))
    for j in prange(rows):
        for i in range(cols):
            acc = 0.0
            for a in range(k):
                v = (j + (a + 0.5) / k) / rows
                for b in range(k):
                    u = (i + (b + 0.5) / k) / cols
                    y0, y1, x0, x1, ty, tx = bilinear_latlong_weights(h, w, u, v)
                    top = (1.0 - tx) * values[y0, x0] + tx * values[y0, x1]
                    bottom = (1.0 - tx) * values[y1, x0] + tx * values[y1, x1]
                    acc += (1.0 - ty) * top + ty * bottom
            out[j, i] = acc / (k * k)
    return out


@jit
def nearest_latlong(image, u, v):
    """The texel containing (u, v): column floor(u W), row floor(v H) (clamped)."""
    h, w = image.shape[0], image.shape[1]
    i = min(max(int(u * w), 0), w - 1)
    j = min(max(int(v * h), 0), h - 1)
    return float(image[j, i, 0]), float(image[j, i, 1]), float(image[j, i, 2])


@jit
def bilinear_clamped(image, s, t):
    """Bilinear lookup of a plain image at (s, t) in [0, 1]^2, texel centres at (i + 0.5)/W, edges clamped."""
    h, w = image.shape[0], image.shape[1]
    fx = min(max(s * w - 0.5, 0.0), w - 1.0)
    fy = min(max(t * h - 0.5, 0.0), h - 1.0)
    x0 = min(int(fx), max(w - 2, 0))
    y0 = min(int(fy), max(h - 2, 0))
    x1 = min(x0 + 1, w - 1)
    y1 = min(y0 + 1, h - 1)
    tx = fx - x0
    ty = fy - y0
    return (
        _bilerp(image, y0, y1, x0, x1, ty, tx, 0),
        _bilerp(image, y0, y1, x0, x1, ty, tx, 1),
        _bilerp(image, y0, y1, x0, x1, ty, tx, 2),
    )


@jit_parallel
def angular_to_latlong_image(angular, height, width, supersampling):
    """Resample a square angular map to a lat-long image, averaging ``supersampling``^2 bilinear lookups per texel."""
    out = np.zeros((height, width, 3), dtype=np.float32)
    inv = 1.0 / (supersampling * supersampling)
    for j in prange(height):
        for i in range(width):
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            for a in range(supersampling):
                for b in range(supersampling):
                    u = (i + (b + 0.5) / supersampling) / width
                    v = (j + (a + 0.5) / supersampling) / height
                    x, y, z = latlong_to_direction(u, v)
                    s, t = direction_to_angular(x, y, z)
                    r, g, bl = bilinear_clamped(angular, s, t)
                    acc0 += r
                    acc1 += g
                    acc2 += bl
            out[j, i, 0] = acc0 * inv
            out[j, i, 1] = acc1 * inv
            out[j, i, 2] = acc2 * inv
    return out


@jit_parallel
def latlong_to_angular_image(latlong, size, supersampling):
    """Resample a lat-long image to a ``size`` x ``size`` angular map (black outside the disc)."""
    out = np.zeros((size, size, 3), dtype=np.float32)
    inv = 1.0 / (supersampling * supersampling)
    for j in prange(size):
        for i in range(size):
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            for a in range(supersampling):
                for b in range(supersampling):
                    s = (i + (b + 0.5) / supersampling) / size
                    t = (j + (a + 0.5) / supersampling) / size
                    x, y, z, inside = angular_to_direction(s, t)
                    if inside:
                        u, v = direction_to_latlong(x, y, z)
                        r, g, bl = bilinear_latlong(latlong, u, v)
                        acc0 += r
                        acc1 += g
                        acc2 += bl
            out[j, i, 0] = acc0 * inv
            out[j, i, 1] = acc1 * inv
            out[j, i, 2] = acc2 * inv
    return out
