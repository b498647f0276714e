"""Orthonormal frames: the local shading frame has the normal on +z.

``coordinate_system(nx, ny, nz)`` is Duff et al. 2017, "Building an Orthonormal Basis, Revisited" (branchless,
continuous except at n = -z where it flips sign consistently).  ``to_local``/``to_world`` express a vector in
the frame (s, t, n) and back.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_parallel, prange

__all__ = ["coordinate_system", "frame_matrix", "normalize", "reflect", "to_local", "to_world"]


@jit
def normalize(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        return 0.0, 0.0, 0.0
    inv = 1.0 / n
    return x * inv, y * inv, z * inv


@jit
def coordinate_system(nx, ny, nz):
    """Two unit vectors s, t with (s, t, n) a right-handed orthonormal basis (Duff et al. 2017)."""
    sign = math.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@jit
def to_local(s, t, n, x, y, z):
    return (
        s[0] * x + s[1] * y + s[2] * z,
        t[0] * x + t[1] * y + t[2] * z,
        n[0] * x + n[1] * y + n[2] * z,
    )


@jit
def to_world(s, t, n, x, y, z):
    return (
        s[0] * x + t[0] * y + n[0] * z,
        s[1] * x + t[1] * y + n[1] * z,
        s[2] * x + t[2] * y + n[2] * z,
    )


@jit
def reflect(x, y, z):
    """Mirror a local-frame direction about the normal (+z): (-x, -y, z)."""
    return -x, -y, z


@jit_parallel
def _frame_rows(axes):
    out = np.empty((axes.shape[0], 3, 3))
    for i in prange(axes.shape[0]):
        n = normalize(axes[i, 0], axes[i, 1], axes[i, 2])
        s, t = coordinate_system(n[0], n[1], n[2])
        for k in range(3):
            out[i, 0, k] = s[k]
            out[i, 1, k] = t[k]
            out[i, 2, k] = n[k]
    return out


def frame_matrix(axis) -> np.ndarray:
    """Rotation matrix whose rows are (s, t, n) for the unit vector ``axis`` (n): ``R @ v`` is v in that frame.

    ``axis`` may be one vector (3,) -> (3, 3) or many (N, 3) -> (N, 3, 3).
    """
    a = np.asarray(axis, dtype=np.float64)
    rows = _frame_rows(np.ascontiguousarray(a.reshape(-1, 3)))
    return rows[0] if a.ndim == 1 else rows
