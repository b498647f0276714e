"""Analytic shapes, intersected exactly in double precision: spheres and rectangles (parallelograms).

A rectangle is a corner ``origin`` and two edge vectors; its normal is normalize(edge_u x edge_v).
:meth:`Rectangle.ground` builds the usual ground square in the plane y = height with normal +Y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError, numeric_array

__all__ = ["Rectangle", "Sphere"]


def _vec3(value, name: str) -> np.ndarray:
    v = numeric_array(value, name, SceneError).reshape(-1)
    # checked as Python floats: NumPy's isfinite and all on three numbers cost 2 us of a scene's 100,000 rectangles
    if v.size != 3 or not all(math.isfinite(x) for x in v.tolist()):
        raise SceneError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


@dataclass(frozen=True)
class Sphere:
    center: np.ndarray
    radius: float

    def __init__(self, center, radius):
        r = float(radius)
        if not (math.isfinite(r) and r > 0.0):
            raise SceneError(f"sphere radius must be a finite number > 0, got {radius!r}")
        object.__setattr__(self, "center", _vec3(center, "sphere center"))
        object.__setattr__(self, "radius", r)

    @property
    def bounds(self) -> np.ndarray:
        return np.stack([self.center - self.radius, self.center + self.radius])


@dataclass(frozen=True)
class Rectangle:
    origin: np.ndarray
    edge_u: np.ndarray
    edge_v: np.ndarray

    def __init__(self, origin, edge_u, edge_v):
        o, a, b = _vec3(origin, "rectangle origin"), _vec3(edge_u, "rectangle edge_u"), _vec3(edge_v, "edge_v")
        # |u x v| written out: np.cross on two 3-vectors costs ~90 us, a scene file may hold 100,000 rectangles
        ax, ay, az = a.tolist()
        bx, by, bz = b.tolist()
        if not math.hypot(ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx) > 0.0:
            raise SceneError("rectangle edges must be non-zero and not parallel")
        object.__setattr__(self, "origin", o)
        object.__setattr__(self, "edge_u", a)
        object.__setattr__(self, "edge_v", b)

    @classmethod
    def ground(cls, *, height: float = 0.0, size: float = 100.0, center=(0.0, 0.0)) -> Rectangle:
        """A square of side ``size`` in the plane y = ``height``, centred at (x, z) = ``center``, normal +Y."""
        s = float(size)
        if not (math.isfinite(s) and s > 0.0):
            raise SceneError(f"ground size must be a finite number > 0, got {size!r}")
        cx, cz = (float(c) for c in center)
        # edge_u = +Z, edge_v = +X: (+Z) x (+X) = +Y
        return cls((cx - s / 2, float(height), cz - s / 2), (0.0, 0.0, s), (s, 0.0, 0.0))

    @property
    def normal(self) -> np.ndarray:
        n = np.cross(self.edge_u, self.edge_v)
        return n / np.linalg.norm(n)

    @property
    def bounds(self) -> np.ndarray:
        corners = self.origin + np.array([[0, 0], [1, 0], [0, 1], [1, 1]]) @ np.stack([self.edge_u, self.edge_v])
        return np.stack([corners.min(axis=0), corners.max(axis=0)])
