"""Procedural lat-long environment maps, so that demos and tests need no files.

:func:`sky_with_sun` follows the peer scene's generator (``../shared/peers/scene.json``, "environment.content"):
a blue gradient sky above a dark ground with a small, very bright sun rasterised with 16x16 sub-texel coverage.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ParameterError

__all__ = ["constant", "sky_with_sun", "sun_direction"]


def constant(radiance=1.0, *, width: int = 8, height: int = 4) -> np.ndarray:
    """A lat-long image of constant radiance (scalar or RGB)."""
    rgb = np.broadcast_to(np.asarray(radiance, dtype=np.float32).reshape(-1), (3,))
    return np.ascontiguousarray(np.broadcast_to(rgb, (height, width, 3)), dtype=np.float32)


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit direction at ``elevation`` above the horizon and lat-long azimuth phi = 2 pi u (u = 0 is -Z)."""
    theta = math.radians(90.0 - elevation_deg)
    phi = math.radians(azimuth_deg)
    return np.array([math.sin(phi) * math.sin(theta), math.cos(theta), -math.cos(phi) * math.sin(theta)])


def sky_with_sun(
    width: int = 1024,
    height: int = 512,
    *,
    sun_elevation_deg: float = 35.0,
    sun_azimuth_deg: float = 45.0,
    sun_diameter_deg: float = 0.5,
    sun_radiance=(40000.0, 38000.0, 34000.0),
    zenith=(0.25, 0.4, 0.85),
    horizon=(0.85, 0.9, 1.0),
    ground=(0.12, 0.1, 0.08),
    supersampling: int = 16,
) -> np.ndarray:
    """Gradient sky + ground + a disc sun, float32 (height, width, 3).

    The defaults reproduce the peer scene's ``env.exr``: sky L = horizon (1 - t) + zenith t with t = sqrt(cos theta)
    above the horizon, ``ground`` below, modulated by 1 + 0.15 sin(2 pi u); the sun blends each texel as
    texel (1 - c) + sun c with c the fraction of ``supersampling``^2 sub-texel points inside the disc.
    """
    if width < 1 or height < 1 or supersampling < 1:
        raise ParameterError("width, height and supersampling must be >= 1")
    if not 0.0 < sun_diameter_deg < 180.0:
        raise ParameterError(f"sun_diameter_deg must be in (0, 180), got {sun_diameter_deg}")
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    c = np.cos(np.pi * v)[:, None, None]
    t = np.sqrt(np.clip(c, 0.0, None))
    sky = np.asarray(horizon) * (1.0 - t) + np.asarray(zenith) * t
    image = np.where(c > 0.0, sky, np.asarray(ground)[None, None, :])
    image = image * (1.0 + 0.15 * np.sin(2.0 * np.pi * u))[None, :, None]

    # sun: coverage of sub-texel points within the angular radius, only near the sun (cheap)
    sun = sun_direction(sun_elevation_deg, sun_azimuth_deg)
    cos_radius = math.cos(math.radians(0.5 * sun_diameter_deg))
    theta_s = math.acos(sun[1])
    margin = math.radians(sun_diameter_deg) + 2.0 * math.pi / min(width, 2 * height)
    rows = np.nonzero(np.abs(np.pi * v - theta_s) <= margin)[0]
    offsets = (np.arange(supersampling) + 0.5) / supersampling
    for j in rows:
        vv = (j + offsets) / height  # (s,)
        uu = (np.arange(width)[:, None] + offsets[None, :]) / width  # (W, s)
        th = np.pi * vv[None, :, None]
        ph = 2.0 * np.pi * uu[:, None, :]
        d = np.stack(
            np.broadcast_arrays(np.sin(ph) * np.sin(th), np.cos(th), -np.cos(ph) * np.sin(th)), axis=-1
        )  # (W, s, s, 3)
        cover = ((d @ sun) >= cos_radius).mean(axis=(1, 2))  # (W,)
        hit = cover > 0
        image[j, hit] = image[j, hit] * (1.0 - cover[hit, None]) + np.asarray(sun_radiance) * cover[hit, None]
    return image.astype(np.float32)
