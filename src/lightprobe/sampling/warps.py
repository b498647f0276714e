"""Warps from the unit square to spheres, hemispheres, lobes, cones and triangles, on NumPy arrays.

Each warp is a triple ``square_to_X(u)``, ``X_pdf(v)``, ``X_to_square(v)``:

* ``u`` is an ``(N, 2)`` array of numbers in [0, 1) (any source: independent, stratified, quasi-random);
  ``u[:, 0]`` drives the azimuth ``phi = 2 pi u0`` of every spherical warp.
* ``v`` is an ``(N, 3)`` array of unit directions in the warp's local frame (its axis on +z), or barycentrics for
  the triangle.
* densities are per unit solid angle (per unit area on the reference triangle).

These functions loop over the scalar Numba kernels of :mod:`lightprobe.sampling.kernels`, which are what the
renderer's kernels call: testing these tests those.

Examples
--------
>>> import numpy as np
>>> from lightprobe.sampling import warps
>>> u = np.random.default_rng(0).random((4, 2))
>>> d = warps.square_to_cosine_hemisphere(u)
>>> np.allclose(warps.cosine_hemisphere_to_square(d), u)
True
"""

from __future__ import annotations

import numpy as np

from .._numba import jit
from .._worksharing import in_threads, read_only
from . import kernels as k

__all__ = [
    "cosine_hemisphere_pdf",
    "cosine_hemisphere_to_square",
    "phong_lobe_pdf",
    "phong_lobe_to_square",
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

# Warp identifiers for the dispatching batch kernels below (one mechanism for all warps).
UNIFORM_SPHERE, UNIFORM_HEMISPHERE, COSINE_HEMISPHERE, PHONG_LOBE, UNIFORM_CONE, UNIFORM_TRIANGLE = range(6)


# Range kernels run by threads (``_worksharing.in_threads``), not ``prange`` loops: the same values (each row is its
# own), and Numba's parallel-loop passes made them slow to compile (decisions.md 129, 131).
@jit
def _sample_range(warp, param, u, out, lo, hi):
    for i in range(lo, hi):
        a, b = u[i, 0], u[i, 1]
        if warp == UNIFORM_SPHERE:
            v = k.square_to_uniform_sphere(a, b)
        elif warp == UNIFORM_HEMISPHERE:
            v = k.square_to_uniform_hemisphere(a, b)
        elif warp == COSINE_HEMISPHERE:
            v = k.square_to_cosine_hemisphere(a, b)
        elif warp == PHONG_LOBE:
            v = k.square_to_phong_lobe(a, b, param)
        elif warp == UNIFORM_CONE:
            v = k.square_to_uniform_cone(a, b, param)
        else:
            v = k.square_to_uniform_triangle(a, b)
        out[i, 0], out[i, 1], out[i, 2] = v


def _sample_batch(warp, param, u):
    out = np.empty((u.shape[0], 3))
    in_threads(_sample_range, u.shape[0], warp, param, u, out)
    return out


@jit
def _pdf_range(warp, param, v, out, lo, hi):
    for i in range(lo, hi):
        x, y, z = v[i, 0], v[i, 1], v[i, 2]
        if warp == UNIFORM_SPHERE:
            p = k.uniform_sphere_pdf(x, y, z)
        elif warp == UNIFORM_HEMISPHERE:
            p = k.uniform_hemisphere_pdf(x, y, z)
        elif warp == COSINE_HEMISPHERE:
            p = k.cosine_hemisphere_pdf(x, y, z)
        elif warp == PHONG_LOBE:
            p = k.phong_lobe_pdf(x, y, z, param)
        elif warp == UNIFORM_CONE:
            p = k.uniform_cone_pdf(x, y, z, param)
        else:
            p = k.uniform_triangle_pdf(x, y, z)
        out[i] = p


def _pdf_batch(warp, param, v):
    out = np.empty(v.shape[0])
    in_threads(_pdf_range, v.shape[0], warp, param, v, out)
    return out


@jit
def _invert_range(warp, param, v, out, lo, hi):
    for i in range(lo, hi):
        x, y, z = v[i, 0], v[i, 1], v[i, 2]
        if warp == UNIFORM_SPHERE:
            s = k.uniform_sphere_to_square(x, y, z)
        elif warp == UNIFORM_HEMISPHERE:
            s = k.uniform_hemisphere_to_square(x, y, z)
        elif warp == COSINE_HEMISPHERE:
            s = k.cosine_hemisphere_to_square(x, y, z)
        elif warp == PHONG_LOBE:
            s = k.phong_lobe_to_square(x, y, z, param)
        elif warp == UNIFORM_CONE:
            s = k.uniform_cone_to_square(x, y, z, param)
        else:
            s = k.uniform_triangle_to_square(x, y, z)
        out[i, 0], out[i, 1] = s


def _invert_batch(warp, param, v):
    out = np.empty((v.shape[0], 2))
    in_threads(_invert_range, v.shape[0], warp, param, v, out)
    return out


def _points(a, width: int, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must be an (N, {width}) array, got shape {arr.shape}")
    return read_only(np.ascontiguousarray(arr))  # one signature of the batch kernels, whatever the caller passed


def _positive(value, name: str) -> float:
    value = float(value)
    if not np.isfinite(value) or value < 0.0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value}")
    return value


def _cos_max(cos_max) -> float:
    value = float(cos_max)
    if not -1.0 <= value < 1.0:
        raise ValueError(f"cos_max must be in [-1, 1), got {value}")
    return value


def square_to_uniform_sphere(u):
    """Uniform directions on the unit sphere; pdf 1/(4 pi)."""
    return _sample_batch(UNIFORM_SPHERE, 0.0, _points(u, 2, "u"))


def uniform_sphere_pdf(v):
    return _pdf_batch(UNIFORM_SPHERE, 0.0, _points(v, 3, "v"))


def uniform_sphere_to_square(v):
    return _invert_batch(UNIFORM_SPHERE, 0.0, _points(v, 3, "v"))


def square_to_uniform_hemisphere(u):
    """Uniform directions on the hemisphere z >= 0; pdf 1/(2 pi)."""
    return _sample_batch(UNIFORM_HEMISPHERE, 0.0, _points(u, 2, "u"))


def uniform_hemisphere_pdf(v):
    return _pdf_batch(UNIFORM_HEMISPHERE, 0.0, _points(v, 3, "v"))


def uniform_hemisphere_to_square(v):
    return _invert_batch(UNIFORM_HEMISPHERE, 0.0, _points(v, 3, "v"))


def square_to_cosine_hemisphere(u):
    """Cosine-weighted directions on z > 0 (Krivanek eqs. 5-10); pdf cos(theta)/pi."""
    return _sample_batch(COSINE_HEMISPHERE, 0.0, _points(u, 2, "u"))


def cosine_hemisphere_pdf(v):
    return _pdf_batch(COSINE_HEMISPHERE, 0.0, _points(v, 3, "v"))


def cosine_hemisphere_to_square(v):
    return _invert_batch(COSINE_HEMISPHERE, 0.0, _points(v, 3, "v"))


def square_to_phong_lobe(u, exponent):
    """Directions about +z with pdf (n+1)/(2 pi) cos^n(theta) (Krivanek eqs. 11-13), n = ``exponent``."""
    return _sample_batch(PHONG_LOBE, _positive(exponent, "exponent"), _points(u, 2, "u"))


def phong_lobe_pdf(v, exponent):
    return _pdf_batch(PHONG_LOBE, _positive(exponent, "exponent"), _points(v, 3, "v"))


def phong_lobe_to_square(v, exponent):
    return _invert_batch(PHONG_LOBE, _positive(exponent, "exponent"), _points(v, 3, "v"))


def square_to_uniform_cone(u, cos_max):
    """Uniform directions in the cone cos(theta) >= ``cos_max`` about +z; pdf 1/(2 pi (1 - cos_max))."""
    return _sample_batch(UNIFORM_CONE, _cos_max(cos_max), _points(u, 2, "u"))


def uniform_cone_pdf(v, cos_max):
    return _pdf_batch(UNIFORM_CONE, _cos_max(cos_max), _points(v, 3, "v"))


def uniform_cone_to_square(v, cos_max):
    return _invert_batch(UNIFORM_CONE, _cos_max(cos_max), _points(v, 3, "v"))


def square_to_uniform_triangle(u):
    """Uniform barycentrics (b0, b1, b2); the point is b0 p0 + b1 p1 + b2 p2."""
    return _sample_batch(UNIFORM_TRIANGLE, 0.0, _points(u, 2, "u"))


def uniform_triangle_pdf(b):
    """Area density on the reference triangle spanned by (b1, b2): 2 inside, 0 outside (1/A for area A)."""
    return _pdf_batch(UNIFORM_TRIANGLE, 0.0, _points(b, 3, "b"))


def uniform_triangle_to_square(b):
    return _invert_batch(UNIFORM_TRIANGLE, 0.0, _points(b, 3, "b"))
