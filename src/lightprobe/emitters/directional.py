"""Directional lights: a sun, infinitely far, as a cone of directions of uniform radiance, or a delta light.

A directional light of irradiance E (at normal incidence, W/m^2 per channel) and angular diameter 2 alpha lights
every point from the same cone of directions about its axis w_l (toward the light), with uniform radiance
L = E / (pi sin^2 alpha): a disc of angular radius alpha gives E = integral over the cone of L cos = pi L sin^2 alpha
at normal incidence.  Its samples are uniform in the cone (pbrt-v4's ``SampleUniformCone``), density
1 / Omega with Omega = 2 pi (1 - cos alpha); a BSDF ray that escapes inside the cone sees L, and MIS weighs it with
that density.  At angle 0 it is pbrt-v4's ``DistantLight``: a delta light with one direction, "radiance" E and
density 1, which no BSDF ray can meet.

Rows of the light table (:class:`~lightprobe.emitters.kinds.LightArrays`): ``geom[0:3]`` the unit direction toward
the light, ``geom[3]`` cos alpha, ``geom[4]`` 1 - cos alpha (2 sin^2(alpha / 2): no cancellation for a sun's
quarter degree), ``geom[5]`` Omega; ``radiance`` L (E at angle 0).  For the light selector, a receiver with normal
n gets the irradiance E max(n . w_l, 1/4) (never 0: a shading normal may see the light where the geometric one
does not).
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_inline
from ..errors import ParameterError
from ..geometry.frame import coordinate_system, to_world
from ..sampling.kernels import TWO_PI
from .kinds import ROW_WIDTH, LightSample

__all__ = ["DirectionalLight", "directional_pdf", "directional_radiance", "directional_sample"]

MAX_ANGLE = 179.0  # degrees of angular diameter: the cone stays in front of a surface that faces the light


@jit_inline
def _inside(g, wx, wy, wz):
    """Whether unit direction w lies in the cone: |w - w_l|^2 = 2 (1 - cos theta) <= 2 (1 - cos alpha)."""
    dx, dy, dz = wx - g[0], wy - g[1], wz - g[2]
    return dx * dx + dy * dy + dz * dz <= 2.0 * g[4]


@jit
def directional_sample(g, radiance, u0, u1):
    """(wx, wy, wz, distance, r, g, b, pdf, delta) of a sample of the light with row ``g``: uniform in its cone, or
    its one direction at angle 0."""
    if g[4] <= 0.0:
        return g[0], g[1], g[2], math.inf, radiance[0], radiance[1], radiance[2], 1.0, True
    one_minus_cos = u1 * g[4]
    cos_t = 1.0 - one_minus_cos
    sin_t = math.sqrt(max(0.0, one_minus_cos * (2.0 - one_minus_cos)))
    phi = TWO_PI * u0
    ts, tt = coordinate_system(g[0], g[1], g[2])
    wx, wy, wz = to_world(ts, tt, (g[0], g[1], g[2]), sin_t * math.cos(phi), sin_t * math.sin(phi), cos_t)
    return wx, wy, wz, math.inf, radiance[0], radiance[1], radiance[2], 1.0 / g[5], False


@jit
def directional_pdf(g, wx, wy, wz):
    """Density per steradian of direction w: 1 / Omega inside the cone, 0 elsewhere and for a delta light."""
    if g[4] <= 0.0 or not _inside(g, wx, wy, wz):
        return 0.0
    return 1.0 / g[5]


@jit
def directional_radiance(g, radiance, wx, wy, wz):
    """Radiance a ray escaping along unit direction w sees from the light: L inside its cone (none from a delta
    light)."""
    if g[4] <= 0.0 or not _inside(g, wx, wy, wz):
        return 0.0, 0.0, 0.0
    return radiance[0], radiance[1], radiance[2]


def _vector(value, name: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = None
    if v is None or isinstance(value, str | bool | dict) or v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ParameterError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


class DirectionalLight:
    """A light infinitely far away, shining along ``direction`` (the way its light travels, as Mitsuba 3's
    ``directional``): ``irradiance`` E (W/m^2 at normal incidence; a number or RGB) from a disc of angular diameter
    ``angle`` degrees (0: a delta light; the sun is about 0.53)."""

    kind = "directional"
    two_sided = False
    area = 0.0

    def __init__(self, direction, irradiance, *, angle: float = 0.0):
        d = _vector(direction, "direction")
        length = float(np.linalg.norm(d))
        if not length > 0.0:
            raise ParameterError("directional light: direction must not be zero")
        self.direction = d / length
        try:
            e = np.asarray(irradiance, dtype=np.float64)
        except (TypeError, ValueError):
            e = None
        if e is not None and e.ndim == 0 and not isinstance(irradiance, bool | str):
            e = np.repeat(e, 3)
        if e is None or isinstance(irradiance, str | bool) or e.shape != (3,) or not np.all(np.isfinite(e)):
            raise ParameterError(f"irradiance must be a number or [r, g, b], finite and >= 0, got {irradiance!r}")
        if np.any(e < 0):
            raise ParameterError(f"irradiance must be a number or [r, g, b], finite and >= 0, got {irradiance!r}")
        if isinstance(angle, bool) or not isinstance(angle, int | float) or not 0.0 <= angle <= MAX_ANGLE:
            raise ParameterError(f"angle must be a number of degrees from 0 to {MAX_ANGLE:g}, got {angle!r}")
        self.irradiance = e
        self.angle = float(angle)

    @property
    def half_angle(self) -> float:
        return math.radians(self.angle) / 2.0

    @property
    def solid_angle(self) -> float:
        """Omega = 2 pi (1 - cos alpha), 0 for a delta light."""
        return TWO_PI * 2.0 * math.sin(self.half_angle / 2.0) ** 2

    @property
    def radiance(self) -> np.ndarray:
        """The disc's radiance L = E / (pi sin^2 alpha); E itself for a delta light (the table's convention)."""
        if self.angle == 0.0:
            return self.irradiance
        return self.irradiance / (math.pi * math.sin(self.half_angle) ** 2)

    @property
    def geom(self) -> np.ndarray:
        g = np.zeros(ROW_WIDTH)
        g[0:3] = -self.direction
        g[3] = math.cos(self.half_angle)
        g[4] = 2.0 * math.sin(self.half_angle / 2.0) ** 2
        g[5] = self.solid_angle
        return g

    def __repr__(self) -> str:
        return (
            f"DirectionalLight(direction={self.direction.tolist()}, irradiance={self.irradiance.tolist()}, "
            f"angle={self.angle})"
        )


# --- the light contract (lights.py's dispatchers call these, generated from kinds.KINDS) ------------------------------
# Every kind's module has the same three functions, inlined into the dispatchers; each calls the kind's own sampler
# with only its own data (a call taking the environment's record cost a light sample 30-70 ns: decisions.md 91).
@jit_inline
def row_sample(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, u0, u1):
    """Directional light l's :class:`~.kinds.LightSample`: :func:`directional_sample`."""
    wx, wy, wz, dist, r, g, b, pdf, delta = directional_sample(lights.geom[l], lights.radiance[l], u0, u1)
    return LightSample(wx, wy, wz, dist, r, g, b, pdf, delta)


@jit_inline
def row_pdf(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, wx, wy, wz):
    """Directional light l's density of direction w: :func:`directional_pdf`."""
    return directional_pdf(lights.geom[l], wx, wy, wz)


@jit_inline
def row_radiance(lights, env, l, wx, wy, wz):
    """What directional light l sends toward a ray leaving the scene along w: :func:`directional_radiance`."""
    return directional_radiance(lights.geom[l], lights.radiance[l], wx, wy, wz)
