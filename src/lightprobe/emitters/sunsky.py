"""A sun and sky from a scene's parameters: the Hosek-Wilkie sky as an environment map and the sun as its own light.

:class:`SunSky` checks the parameters of ``[environment] type = "sunsky"`` (and ``--sunsky``) as Mitsuba 3.9.1's
``sunsky`` names them, and gives the sky baked into a lat-long map (:meth:`SunSky.environment`) and the sun's light
(:meth:`SunSky.sun`, :class:`~lightprobe.emitters.sun.SunLight`).  The model itself is
:mod:`lightprobe.emitters.hosek_wilkie`, which the sun's kernels read too (a module of its own, so that neither this
module nor the sun's imports the other in a circle).
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from ..errors import ParameterError
from .envmap import EnvironmentMap
from .hosek_wilkie import (
    SUN_APERTURE,
    TURBIDITY_RANGE,
    _describe_when,
    _number,
    sky_image,
    sky_state,
    sun_position,
)
from .procedural import sun_direction as direction_of_sun
from .sun import SunLight

__all__ = ["SunSky"]


class SunSky:
    """A Hosek-Wilkie sun and sky (Mitsuba 3.9.1's ``sunsky``; ``limb_darkening`` is its ``complex_sun``).

    ``turbidity`` 1-10; ``albedo`` the ground's, 0-1 (a number or RGB); the sun at ``sun_elevation`` degrees above
    the horizon (0-90) and lat-long ``sun_azimuth`` degrees, or along the world ``sun_direction`` toward it (y >= 0),
    or where it stands at the date, time and place ``when`` (a dict of :func:`sun_position`'s keys);
    ``limb_darkening`` (default true) the sun's radiance over its disc from the solar radiance function, else
    Mitsuba's default uniform disc; ``sun_scale`` and ``sky_scale`` (>= 0, not both 0) multiply the two;
    ``sun_aperture`` is the sun's angular diameter in degrees (0-90, exclusive; its irradiance is kept).
    :meth:`environment` is the sky as a lat-long environment map (``width`` x ``width / 2 + 1``), :meth:`sun` the
    sun's light.
    """

    def __init__(
        self,
        *,
        turbidity: float = 3.0,
        albedo=0.3,
        sun_elevation: float | None = None,
        sun_azimuth: float = 0.0,
        sun_direction=None,
        sun_scale: float = 1.0,
        sky_scale: float = 1.0,
        sun_aperture: float = SUN_APERTURE,
        width: int = 1024,
        when: dict | None = None,
        limb_darkening: bool = True,
    ):
        self.turbidity = _number(turbidity, "turbidity", *TURBIDITY_RANGE)
        if not isinstance(limb_darkening, bool):
            raise ParameterError(f"sunsky: limb_darkening must be true or false, got {limb_darkening!r}")
        self.limb_darkening = limb_darkening
        a = np.asarray(albedo, dtype=np.float64) if not isinstance(albedo, str | bool) else None
        if a is not None and a.ndim == 0:
            a = np.repeat(a, 3)
        if a is None or a.shape != (3,) or not np.all((a >= 0.0) & (a <= 1.0)):
            raise ParameterError(f"sunsky: albedo must be a number or [r, g, b] from 0 to 1, got {albedo!r}")
        self.albedo = a
        self.sun_scale = _number(sun_scale, "sun_scale", 0.0, math.inf)
        self.sky_scale = _number(sky_scale, "sky_scale", 0.0, math.inf)
        if self.sun_scale == 0.0 and self.sky_scale == 0.0:
            raise ParameterError("sunsky: sun_scale and sky_scale are both 0: nothing would emit light")
        self.sun_aperture = _number(sun_aperture, "sun_aperture", 0.0, 90.0, " degrees")
        if not 0.0 < self.sun_aperture < 90.0:
            raise ParameterError(f"sunsky: sun_aperture must be in (0, 90) degrees, got {sun_aperture!r}")
        if isinstance(width, bool) or not isinstance(width, int) or width < 8:
            raise ParameterError(f"sunsky: width must be an integer of at least 8, got {width!r}")
        self.width = width
        if when is not None:
            if sun_direction is not None or sun_elevation is not None:
                raise ParameterError("sunsky: give the sun's date, time and place or its direction, not both")
            sun_direction = sun_position(**when)
            if sun_direction[1] < 0.0:
                raise ParameterError(
                    f"sunsky: the sun is below the horizon at {_describe_when(when)}; Mitsuba's sky is then black"
                )
        if sun_direction is not None:
            if sun_elevation is not None:
                raise ParameterError("sunsky: give the sun's sun_direction or its sun_elevation, not both")
            try:
                d = np.asarray(sun_direction, dtype=np.float64)
            except (TypeError, ValueError):
                d = None
            if d is None or d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0.0:
                raise ParameterError(
                    f"sunsky: sun_direction must be 3 finite numbers, not all 0, got {sun_direction!r}"
                )
            d = d / np.linalg.norm(d)
            if d[1] < 0.0:
                raise ParameterError(
                    f"sunsky: sun_direction {np.asarray(sun_direction).tolist()} is below the horizon (y < 0); "
                    "Mitsuba's sky is then black"
                )
            self.direction = d
        else:
            elevation = 45.0 if sun_elevation is None else sun_elevation
            if isinstance(elevation, numbers.Real) and not isinstance(elevation, bool) and elevation < 0.0:
                raise ParameterError(
                    f"sunsky: sun_elevation {elevation!r} is below the horizon; Mitsuba's sky is then black "
                    "(give 0 to 90 degrees)"
                )
            elevation = _number(elevation, "sun_elevation", 0.0, 90.0, " degrees")
            azimuth = _number(sun_azimuth, "sun_azimuth", -360.0, 360.0, " degrees")
            self.direction = direction_of_sun(elevation, azimuth)
        # the sun's elevation from its direction, as Mitsuba's (it converts the direction to angles)
        self.elevation = math.pi / 2.0 - math.acos(min(1.0, max(-1.0, float(self.direction[1]))))
        self.params, self.scale = sky_state(self.turbidity, self.albedo, self.elevation)

    def sky_image(self, width: int | None = None) -> np.ndarray:
        """The sky (times ``sky_scale``) as a lat-long image, ``width`` x ``width / 2 + 1`` (the horizon a row)."""
        w = width or self.width
        return self.sky_scale * sky_image(self.direction, self.params, self.scale, width=w, height=w // 2 + 1)

    def environment(self):
        """The sky as an :class:`~lightprobe.emitters.envmap.EnvironmentMap` (None when ``sky_scale`` is 0).

        The RGB fit goes slightly negative near the horizon in a few settings (-0.0014, 1 % of the sky there, at
        turbidity 10 with the sun 3 degrees up); Mitsuba keeps such values, the map's sampler needs radiance >= 0,
        so they are clamped to 0 here."""
        if self.sky_scale == 0.0:
            return None
        return EnvironmentMap.from_array(np.maximum(self.sky_image(), 0.0), source="sunsky")

    def sun(self):
        """The sun as a :class:`~lightprobe.emitters.sun.SunLight` (None when ``sun_scale`` is 0)."""
        if self.sun_scale == 0.0:
            return None
        return SunLight(
            self.direction,
            turbidity=self.turbidity,
            aperture=self.sun_aperture,
            scale=self.sun_scale,
            limb_darkening=self.limb_darkening,
        )

    def __repr__(self) -> str:
        return (
            f"SunSky(turbidity={self.turbidity:g}, albedo={self.albedo.tolist()}, "
            f"sun_direction={np.round(self.direction, 6).tolist()}, sun_scale={self.sun_scale:g}, "
            f"sky_scale={self.sky_scale:g}, sun_aperture={self.sun_aperture:g})"
        )
