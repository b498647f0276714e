"""The sun of the Hosek-Wilkie sun and sky: a limb-darkened disc infinitely far away.

A light kind of its own (``sun`` in :data:`~lightprobe.emitters.kinds.KINDS`): like a directional light of nonzero
angle (emitters/directional.py) it lights every point from one cone of directions of half-angle alpha about the
direction toward the sun, and is sampled uniformly in that cone (pbrt-v4's ``SampleUniformCone``, as Mitsuba 3's
``sunsky`` samples its sun), density 1 / Omega with Omega = 2 pi (1 - cos alpha); but its radiance varies over the
disc: the Hosek-Wilkie 2013 solar radiance function, a polynomial in the elevation of the direction looked along and
in the limb-darkening cosine mu (emitters/hosek_wilkie.py's docstring has the model; the table is Mitsuba's RGB one,
with the limb darkening baked in).  The sampling is not proportional to the radiance (the limb is about half as
bright as the centre), but the disc is a quarter of a degree wide: every sample lands on the sun, and the weight
L / p varies by that factor only.

Row of the light table (:class:`~lightprobe.emitters.kinds.LightArrays`): ``geom[0:6]`` as a directional light's
(unit direction toward the sun, cos alpha, 1 - cos alpha, Omega), so the cone's sampling and density are
directional.py's own functions; ``geom[6]`` the turbidity less 1 (the table's index, interpolated linearly as
Mitsuba's); ``geom[7]`` 1 / sin^2 alpha (for mu); ``geom[8]`` the factor the polynomial is multiplied by
(:func:`~lightprobe.emitters.hosek_wilkie.sun_scale_factor`); ``geom[9]`` 1 for the limb-darkened sun, 0 for Mitsuba's
uniform one.  ``radiance`` holds the disc's mean radiance (the uniform sun's radiance), so that the light
selector's irradiance of a directional row, pi L sin^2 alpha, is the sun's.

Mitsuba's values can be slightly negative in blue near the limb of a sun a few degrees up at high turbidity (its RGB
fit; its documentation leaves such values unclamped): so are these.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit, jit_inline
from ..errors import ParameterError
from .directional import _inside, _vector, directional_pdf, directional_sample
from .hosek_wilkie import (
    SUN_APERTURE,
    SUN_SEGMENTS,
    TURBIDITY_RANGE,
    _tables,
    disc_angles,
    sun_radiance,
    sun_scale_factor,
    uniform_sun_radiance,
)
from .kinds import ROW_WIDTH, LightSample

__all__ = ["SunLight", "sun_disc_radiance", "sun_pdf", "sun_sample"]

# (10 turbidities, 45 elevation segments, 3 channels, 4 powers of x, 6 powers of mu): a global array, which Numba
# compiles in as a constant (the table is fixed data, the same for every sun; the kernel cache is stamped by the
# sources, not by the data file, so a new table needs a fresh cache)
SUN_TABLE = np.ascontiguousarray(_tables()["sun_radiance"])
_HALF_PI = 0.5 * math.pi
_TURBIDITY_STEPS = SUN_TABLE.shape[0] - 1


@jit_inline
def _channel(i, f, segment, c, x, mu):
    """sum_k sum_j T[segment, c, k, j] x^k mu^j, T the table at turbidity index i + f (linear, as Mitsuba's)."""
    total = 0.0
    x_power = 1.0
    for k in range(4):
        mu_power = 1.0
        for j in range(6):
            coefficient = SUN_TABLE[i, segment, c, k, j] * (1.0 - f) + SUN_TABLE[i + 1, segment, c, k, j] * f
            total += coefficient * x_power * mu_power
            mu_power *= mu
        x_power *= x
    return total


@jit
def sun_disc_radiance(g, radiance, wx, wy, wz):
    """RGB radiance of the sun with row ``g`` seen along unit direction w: zero outside its disc and below the
    horizon; inside, the solar radiance polynomial of emitters/hosek_wilkie.py at w's elevation and limb cosine, or, for
    the uniform sun (``g[9]`` 0), its row's ``radiance``."""
    if wy < 0.0 or not _inside(g, wx, wy, wz):
        return 0.0, 0.0, 0.0
    if g[9] == 0.0:
        return radiance[0], radiance[1], radiance[2]
    dx, dy, dz = wx - g[0], wy - g[1], wz - g[2]
    gamma = 2.0 * math.asin(min(1.0, 0.5 * math.sqrt(dx * dx + dy * dy + dz * dz)))  # accurate near 0
    sin_gamma = math.sin(gamma)
    mu = math.sqrt(max(0.0, 1.0 - sin_gamma * sin_gamma * g[7]))
    eta = _HALF_PI - math.acos(min(1.0, wy))  # the direction's elevation, as Mitsuba computes it
    segment = min(math.floor((eta / _HALF_PI) ** (1.0 / 3.0) * SUN_SEGMENTS), SUN_SEGMENTS - 1)
    x = eta - _HALF_PI * (segment / SUN_SEGMENTS) ** 3
    t = g[6]
    i = min(int(t), _TURBIDITY_STEPS - 1)
    f = t - i
    return (
        _channel(i, f, segment, 0, x, mu) * g[8],
        _channel(i, f, segment, 1, x, mu) * g[8],
        _channel(i, f, segment, 2, x, mu) * g[8],
    )


@jit
def sun_sample(g, radiance, u0, u1):
    """(wx, wy, wz, distance, r, g, b, pdf) of a sample of the sun with row ``g``: uniform in its cone (the
    directional light's sampler), with the disc's radiance at the sampled direction."""
    wx, wy, wz, dist, _, _, _, pdf, _ = directional_sample(g, radiance, u0, u1)
    r, gg, b = sun_disc_radiance(g, radiance, wx, wy, wz)
    return wx, wy, wz, dist, r, gg, b, pdf


@jit
def sun_pdf(g, wx, wy, wz):
    """Density per steradian of direction w: 1 / Omega inside the sun's cone, 0 elsewhere."""
    return directional_pdf(g, wx, wy, wz)


class SunLight:
    """The Hosek-Wilkie sun toward world direction ``sun_direction`` (y >= 0: above the horizon), at
    ``turbidity`` 1-10, a disc of angular diameter ``aperture`` degrees (its irradiance kept that of the standard
    0.5358-degree sun, as Mitsuba's) times ``scale``; ``limb_darkening`` (Mitsuba's ``complex_sun``) its radiance
    over the disc from the solar radiance function, else Mitsuba's default uniform disc
    (:func:`~lightprobe.emitters.hosek_wilkie.uniform_sun_radiance`)."""

    kind = "sun"
    two_sided = False
    area = 0.0

    def __init__(
        self,
        sun_direction,
        *,
        turbidity: float = 3.0,
        aperture: float = SUN_APERTURE,
        scale: float = 1.0,
        limb_darkening: bool = True,
    ):
        d = _vector(sun_direction, "sun: sun_direction")
        length = float(np.linalg.norm(d))
        if not length > 0.0:
            raise ParameterError("sun: sun_direction must not be zero")
        if d[1] < 0.0:
            raise ParameterError(f"sun: sun_direction {d.tolist()} is below the horizon (y < 0)")
        for name, value, lo, hi in (("turbidity", turbidity, *TURBIDITY_RANGE), ("aperture", aperture, 0.0, 90.0)):
            if isinstance(value, bool) or not isinstance(value, int | float) or not lo <= value <= hi:
                raise ParameterError(f"sun: {name} must be a number from {lo:g} to {hi:g}, got {value!r}")
        if not 0.0 < aperture < 90.0:
            raise ParameterError(f"sun: aperture must be in (0, 90) degrees, got {aperture!r}")
        if isinstance(scale, bool) or not isinstance(scale, int | float) or not 0.0 < scale < math.inf:
            raise ParameterError(f"sun: scale must be a finite number > 0, got {scale!r}")
        if not isinstance(limb_darkening, bool):
            raise ParameterError(f"sun: limb_darkening must be true or false, got {limb_darkening!r}")
        self.limb_darkening = limb_darkening
        self.sun_direction = d / length
        self.turbidity = float(turbidity)
        self.aperture = float(aperture)
        self.scale = float(scale)

    @property
    def half_angle(self) -> float:
        """alpha in radians (:func:`~lightprobe.emitters.hosek_wilkie.disc_angles`: Mitsuba's float32 value)."""
        return disc_angles(self.aperture)[0]

    @property
    def cos_half_angle(self) -> float:
        """cos alpha as Mitsuba's disc has it, rounded to float32
        (:func:`~lightprobe.emitters.hosek_wilkie.disc_angles`)."""
        return disc_angles(self.aperture)[1]

    @property
    def solid_angle(self) -> float:
        """Omega = 2 pi (1 - cos alpha)."""
        return 2.0 * math.pi * (1.0 - self.cos_half_angle)

    @property
    def geom(self) -> np.ndarray:
        g = np.zeros(ROW_WIDTH)
        g[0:3] = self.sun_direction
        g[3] = self.cos_half_angle
        g[4] = 1.0 - self.cos_half_angle  # exact: a float32 near 1 less 1
        g[5] = self.solid_angle
        g[6] = min(max(self.turbidity - 1.0, 0.0), float(_TURBIDITY_STEPS))
        g[7] = 1.0 / math.sin(self.half_angle) ** 2
        g[8] = sun_scale_factor(self.aperture, self.scale)
        g[9] = 1.0 if self.limb_darkening else 0.0
        return g

    def radiance_at(self, dirs) -> np.ndarray:
        """Radiance (N, 3) seen along unit directions (NumPy: the reference the kernel is tested against)."""
        if self.limb_darkening:
            return sun_radiance(dirs, self.sun_direction, self.turbidity, self.aperture, self.scale)
        d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        seen = (d @ self.sun_direction >= self.cos_half_angle) & (d[:, 1] >= 0.0)
        return np.where(seen[:, None], self._uniform_radiance()[None, :], 0.0)

    def _uniform_radiance(self) -> np.ndarray:
        elevation = math.pi / 2.0 - math.acos(min(1.0, float(self.sun_direction[1])))
        return uniform_sun_radiance(self.turbidity, elevation, self.aperture, self.scale)

    @property
    def radiance(self) -> np.ndarray:
        """The disc's mean radiance (3,): the uniform sun's own; the limb-darkened one's by the midpoint rule over
        48 rings of equal solid angle x 48 azimuths."""
        if not self.limb_darkening:
            return self._uniform_radiance()
        rings, around = 48, 48
        one_minus_cos = (np.arange(rings) + 0.5) / rings * (1.0 - self.cos_half_angle)
        cos_t = 1.0 - one_minus_cos
        sin_t = np.sqrt(np.maximum(0.0, one_minus_cos * (2.0 - one_minus_cos)))
        phi = 2.0 * math.pi * (np.arange(around) + 0.5) / around
        axis = self.sun_direction
        t = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 0.0, 1.0])
        t /= np.linalg.norm(t)
        b = np.cross(axis, t)
        local = np.cos(phi)[None, :, None] * t + np.sin(phi)[None, :, None] * b
        dirs = cos_t[:, None, None] * axis + sin_t[:, None, None] * local
        return self.radiance_at(dirs.reshape(-1, 3)).mean(axis=0)

    def __repr__(self) -> str:
        return (
            f"SunLight(sun_direction={np.round(self.sun_direction, 6).tolist()}, turbidity={self.turbidity:g}, "
            f"aperture={self.aperture:g}, scale={self.scale:g})"
        )


# --- the light contract (lights.py's dispatchers call these, generated from kinds.KINDS) ------------------------------
@jit_inline
def row_sample(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, u0, u1):
    """The sun's :class:`~.kinds.LightSample`: uniform in its cone (:func:`sun_sample`)."""
    wx, wy, wz, dist, r, g, b, pdf = sun_sample(lights.geom[l], lights.radiance[l], u0, u1)
    return LightSample(wx, wy, wz, dist, r, g, b, pdf, False)


@jit_inline
def row_pdf(lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, wx, wy, wz):
    """The sun's density of direction w: 1 / Omega inside its cone (:func:`sun_pdf`)."""
    return sun_pdf(lights.geom[l], wx, wy, wz)


@jit_inline
def row_radiance(lights, env, l, wx, wy, wz):
    """What the sun's disc shows a ray leaving the scene along w (:func:`sun_disc_radiance`)."""
    return sun_disc_radiance(lights.geom[l], lights.radiance[l], wx, wy, wz)
