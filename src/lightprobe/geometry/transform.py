"""4x4 affine transforms (row-major, acting on column vectors: p_world = M [p, 1]).

A transform is given either as ``matrix`` (4x4, or 3x4) or as any of ``scale`` (number or 3 numbers),
``rotate`` (``[axis_x, axis_y, axis_z, angle_degrees]``, or a list of them applied in order) and ``translate``
(3 numbers), applied in that order: scale, then rotate, then translate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..errors import SceneError, numeric_array

__all__ = ["make_transform", "rotation_matrix"]


def rotation_matrix(axis, angle_deg: float) -> np.ndarray:
    """3x3 rotation by ``angle_deg`` about ``axis`` (right-handed, Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(a)
    if a.shape != (3,) or not n > 0 or not math.isfinite(float(angle_deg)):
        raise SceneError(f"rotate needs a non-zero axis and a finite angle, got axis={axis!r} angle={angle_deg!r}")
    x, y, z = a / n
    t = math.radians(float(angle_deg))
    c, s, k = math.cos(t), math.sin(t), 1.0 - math.cos(t)
    return np.array(
        [
            [c + x * x * k, x * y * k - z * s, x * z * k + y * s],
            [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
            [z * x * k - y * s, z * y * k + x * s, c + z * z * k],
        ]
    )


def make_transform(spec: Mapping | None) -> np.ndarray:
    """A 4x4 matrix from a transform description (see the module docstring); None is the identity."""
    m = np.eye(4)
    if spec is None:
        return m
    if not isinstance(spec, Mapping):
        raise SceneError(f"transform must be a table with matrix or scale/rotate/translate, got {spec!r}")
    unknown = set(spec) - {"matrix", "scale", "rotate", "translate"}
    if unknown:
        raise SceneError(f"unknown transform keys {sorted(unknown)}; use matrix, scale, rotate, translate")
    if "matrix" in spec:
        if len(spec) > 1:
            raise SceneError("give either matrix or scale/rotate/translate, not both")
        given = numeric_array(spec["matrix"], "transform matrix", SceneError)
        if given.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(given)):
            raise SceneError("transform matrix must be 4x4 (or 3x4) finite numbers")
        m[: given.shape[0]] = given
        if abs(np.linalg.det(m[:3, :3])) < 1e-300:
            raise SceneError("transform matrix is singular")
        return m
    if "scale" in spec:
        s = numeric_array(spec["scale"], "scale", SceneError).reshape(-1)
        if s.size == 1:
            s = np.repeat(s, 3)
        if s.size != 3 or not np.all(np.isfinite(s)) or np.any(s == 0):
            raise SceneError(f"scale must be one or three finite non-zero numbers, got {spec['scale']!r}")
        m = np.diag([*s, 1.0]) @ m
    if "rotate" in spec:
        rotations = numeric_array(spec["rotate"], "rotate", SceneError)
        if rotations.ndim == 1:
            rotations = rotations[None]
        if rotations.ndim != 2 or rotations.shape[1] != 4 or rotations.shape[0] < 1:
            raise SceneError(f"rotate entries are [axis_x, axis_y, axis_z, angle_degrees], got {spec['rotate']!r}")
        for r in rotations:
            rot = np.eye(4)
            rot[:3, :3] = rotation_matrix(r[:3], r[3])
            m = rot @ m
    if "translate" in spec:
        t = numeric_array(spec["translate"], "translate", SceneError).reshape(-1)
        if t.size != 3 or not np.all(np.isfinite(t)):
            raise SceneError(f"translate must be three finite numbers, got {spec['translate']!r}")
        tr = np.eye(4)
        tr[:3, 3] = t
        m = tr @ m
    return m
