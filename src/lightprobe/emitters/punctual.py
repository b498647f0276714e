"""Point and spot lights: delta lights in the light table, after pbrt-v4's ``PointLight`` and ``SpotLight``.

A delta light has a position and no area.  From a reference point p it lights along exactly one direction, so:

* its sample is that direction, the distance to the light, the radiance arriving I(w) / d^2 and a "density" of 1:
  the estimator f L cos / p divides by the light's selection probability alone (pbrt-v4's ``SampleLi`` returns
  pdf 1 for delta lights the same way);
* no BSDF or hemisphere direction ever meets it (its density for any given direction is 0), so its samples take
  MIS weight 1: the renderer passes a BSDF density of 0 to the weight.  The BSDF-only and hemisphere strategies
  cannot see it at all, as in every renderer.

Rows of the light table (:class:`~lightprobe.emitters.kinds.LightArrays`): ``geom[0:3]`` the position; a spot's unit
axis in ``geom[3:6]``, the cosine of its total half-angle in ``geom[6]`` and of the angle where its falloff begins in
``geom[7]``; ``radiance`` is the intensity I (W/sr per channel, along the axis for a spot); area 0.  A spot's
intensity at angle theta from its axis is I x smoothstep(cos theta, cos total, cos falloff start) (pbrt-v4).

Powers (the ``power`` selector's weights): a point light 4 pi I, a spot 2 pi I (1 - (cos_start + cos_total) / 2)
(pbrt-v4's ``SpotLight::Phi``).
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_inline
from ..errors import ParameterError
from .kinds import LIGHT_SPOT, ROW_WIDTH, LightSample

__all__ = ["PointLight", "SpotLight", "punctual_power", "punctual_sample", "spot_falloff"]


@jit
def spot_falloff(cos_theta, cos_total, cos_start):
    """pbrt-v4's SmoothStep(cos theta, cos total, cos start): 0 outside the cone, 1 inside the falloff start."""
    if cos_start <= cos_total:
        return 1.0 if cos_theta >= cos_total else 0.0
    t = min(max((cos_theta - cos_total) / (cos_start - cos_total), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


@jit
def punctual_sample(is_spot, g, intensity, px, py, pz):
    """The one direction from p toward a point or spot light with geometry row g: (wx, wy, wz, distance, r, g, b,
    pdf), pdf 1 (a delta), radiance I(w) / d^2; pdf 0 at the light's own position (no direction)."""
    dx, dy, dz = g[0] - px, g[1] - py, g[2] - pz
    d2 = dx * dx + dy * dy + dz * dz
    if not d2 > 0.0:
        return 0.0, 0.0, 1.0, math.inf, 0.0, 0.0, 0.0, 0.0
    dist = math.sqrt(d2)
    wx, wy, wz = dx / dist, dy / dist, dz / dist
    scale = 1.0 / d2
    if is_spot:
        scale *= spot_falloff(-(wx * g[3] + wy * g[4] + wz * g[5]), g[6], g[7])
    return wx, wy, wz, dist, intensity[0] * scale, intensity[1] * scale, intensity[2] * scale, 1.0


def punctual_power(is_spot: np.ndarray, geom: np.ndarray, intensity: np.ndarray) -> np.ndarray:
    """Emitted power of the luminance of point lights (4 pi I) and spot lights (2 pi I (1 - (cos_start +
    cos_total) / 2), pbrt-v4's ``Phi``), one per row."""
    from ..color import luminance

    lum = luminance(intensity)
    spot = 2.0 * math.pi * lum * (1.0 - 0.5 * (geom[:, 7] + geom[:, 6]))
    return np.where(is_spot, spot, 4.0 * math.pi * lum)


def _floats(value) -> np.ndarray | None:
    """``value`` as float64 numbers, or None if it is not numbers (a string, a table, booleans)."""
    if isinstance(value, bool | str | dict):
        return None
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return v


def _vector(value, name: str) -> np.ndarray:
    v = _floats(value)
    if v is None or v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ParameterError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


def _intensity(value) -> np.ndarray:
    v = _floats(value)
    if v is not None and v.ndim == 0:
        v = np.repeat(v, 3)
    if v is None or v.shape != (3,) or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ParameterError(f"intensity must be a number or [r, g, b], finite and >= 0, got {value!r}")
    return v


class PointLight:
    """A point light at ``position`` with intensity ``intensity`` (W/sr; a number or RGB) in every direction."""

    kind = "point"
    two_sided = False
    area = 0.0

    def __init__(self, position, intensity):
        self.position = _vector(position, "position")
        self.radiance = _intensity(intensity)  # the table's radiance column holds a delta light's intensity

    @property
    def geom(self) -> np.ndarray:
        g = np.zeros(ROW_WIDTH)
        g[0:3] = self.position
        return g

    @property
    def power(self) -> float:
        """The emitted power of the luminance, as the ``power`` selector weighs it."""
        return float(punctual_power(np.array([self.kind == "spot"]), self.geom[None, :], self.radiance[None, :])[0])

    def __repr__(self) -> str:
        return f"PointLight(position={self.position.tolist()}, intensity={self.radiance.tolist()})"


class SpotLight(PointLight):
    """A spot light at ``position`` aimed at ``target``: intensity ``intensity`` along its axis, falling off
    smoothly from ``falloff_start`` to ``cone_angle`` degrees off it (pbrt-v4's ``coneangle`` and
    ``conedelta`` = cone_angle - falloff_start), none beyond."""

    kind = "spot"

    def __init__(self, position, target, intensity, *, cone_angle: float = 30.0, falloff_start: float | None = None):
        super().__init__(position, intensity)
        axis = _vector(target, "target") - self.position
        length = float(np.linalg.norm(axis))
        if not length > 0.0:
            raise ParameterError("spot light: target must differ from position")
        self.axis = axis / length
        start = cone_angle - 5.0 if falloff_start is None else falloff_start
        if not (isinstance(cone_angle, int | float) and 0.0 < cone_angle <= 90.0):
            raise ParameterError(f"cone_angle must be a number of degrees in (0, 90], got {cone_angle!r}")
        if not (isinstance(start, int | float) and start <= cone_angle):
            raise ParameterError(f"falloff_start must be a number of degrees <= cone_angle, got {falloff_start!r}")
        self.cone_angle, self.falloff_start = float(cone_angle), max(0.0, float(start))

    @property
    def cos_total(self) -> float:
        return math.cos(math.radians(self.cone_angle))

    @property
    def cos_start(self) -> float:
        return math.cos(math.radians(self.falloff_start))

    @property
    def geom(self) -> np.ndarray:
        g = super().geom
        g[3:6] = self.axis
        g[6], g[7] = self.cos_total, self.cos_start
        return g

    def __repr__(self) -> str:
        return (
            f"SpotLight(position={self.position.tolist()}, axis={self.axis.tolist()}, "
            f"intensity={self.radiance.tolist()}, cone_angle={self.cone_angle}, falloff_start={self.falloff_start})"
        )


# --- the light contract (lights.py's dispatchers call these, generated from kinds.KINDS) ------------------------------
# Every kind's module has the same three functions, inlined into the dispatchers; each calls the kind's own sampler
# with only its own data (a call taking the environment's record cost a light sample 30-70 ns: decisions.md 91).
@jit_inline
def row_sample(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, u0, u1):
    """Point or spot light l's one direction from p: :func:`punctual_sample`, a delta light."""
    wx, wy, wz, dist, r, g, b, pdf = punctual_sample(
        lights.kind[l] == LIGHT_SPOT, lights.geom[l], lights.radiance[l], px, py, pz
    )
    return LightSample(wx, wy, wz, dist, r, g, b, pdf, True)


@jit_inline
def row_pdf(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, wx, wy, wz):
    """0: no given direction is ever a delta light's."""
    return 0.0
