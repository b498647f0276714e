"""The Hosek-Wilkie sun and sky model, as Mitsuba 3.9.1's ``sunsky`` emitter computes it in RGB.

The sky (Hosek & Wilkie 2012, "An Analytic Model for Full Spectral Sky-Dome Radiance", eq. 9) gives the radiance
of a direction at angle theta from the zenith and gamma from the sun as

    L = (1 + A exp(B / (cos theta + 0.01))) (C + D exp(E gamma) + F cos^2 gamma + G chi(H, gamma) + I sqrt(cos theta)) R
    chi(g, gamma) = (1 + cos^2 gamma) / (1 + g^2 - 2 g cos gamma)^(3/2)

per RGB channel, with the nine parameters and the scale R interpolated from the published tables: linearly in
turbidity (1-10) and in ground albedo (0-1, per channel), and over the sun's elevation eta by a quintic Bezier curve
in x = (eta / (pi / 2))^(1/3) (the tables' six control points).  Mitsuba's data hold the nine parameters in its own
order: index 7 multiplies sqrt(cos theta) and index 8 is chi's g; this module reads them as Mitsuba does.  Every
direction below the horizon (cos theta < 0) is black, as Mitsuba's.  Mitsuba's RGB values are the model's times
``CIE_Y_NORMALIZATION`` (1 / 106.75...: its spectral-to-RGB normalisation; the model's spectral units are
W m^-2 sr^-1 nm^-1, so a scene is meant to be in metres).

The sun (Hosek & Wilkie 2013, "Adding a Solar-Radiance Function to the Hosek-Wilkie Skylight Model") is the tables'
piecewise polynomial over the elevation of the direction looked along, with the limb darkening baked in (Mitsuba's
RGB table, its ``complex_sun = true``): for eta the direction's elevation, segment s = floor(45 (eta / (pi/2))^(1/3)),
x = eta - (pi / 2) (s / 45)^3, and mu = sqrt(1 - sin^2 gamma / sin^2 alpha) the cosine on the solar disc of angular
radius alpha,

    L_c = sum_k sum_j T[s, c, k, j] x^k mu^j     (k < 4, j < 6; T interpolated linearly in turbidity)

times (1 - cos alpha_0) / (1 - cos alpha) (alpha_0 the standard sun's 0.2679 degrees: a larger disc keeps the
sun's irradiance), Mitsuba's ``SPEC_TO_RGB_SUN_CONV`` and ``CIE_Y_NORMALIZATION``.  The sun is its own light
(:mod:`lightprobe.emitters.sun`); the sky is baked into a lat-long map for the environment light
(:func:`sky_image`; :class:`~lightprobe.emitters.sunsky.SunSky` puts the two together).

Frames: lightprobe is Y up; the sky's zenith is +Y and the sun's azimuth follows the lat-long map
(:func:`lightprobe.emitters.procedural.sun_direction`).  In Mitsuba that is ``to_world = rotate([1, 0, 0], -90)``
and ``sun_direction`` the same world direction (../shared/notes/sunsky-mitsuba.md).
"""

from __future__ import annotations

import functools
import math
import numbers
from pathlib import Path

import numpy as np

from ..errors import ParameterError

__all__ = [
    "CIE_Y_NORMALIZATION",
    "SUN_APERTURE",
    "disc_angles",
    "sky_image",
    "sky_radiance",
    "sky_state",
    "sun_position",
    "sun_radiance",
    "sun_table",
    "uniform_sun_radiance",
]

DATA = Path(__file__).resolve().parent / "data" / "sunsky_rgb.npz"
CIE_Y_NORMALIZATION = 1.0 / 106.7502593994140625  # Mitsuba 3's MI_CIE_Y_NORMALIZATION (include/mitsuba/core/spectrum.h)
SPEC_TO_RGB_SUN_CONV = 467.069280386  # Mitsuba 3's constant for its RGB sun table (include/mitsuba/render/sunsky.h)
SUN_APERTURE = 0.5358  # degrees: the sun's angular diameter the tables were fitted for (Mitsuba's default)
SUN_SEGMENTS = 45
TURBIDITY_RANGE = (1.0, 10.0)
_BEZIER = (1.0, 5.0, 10.0, 10.0, 5.0, 1.0)  # binomial coefficients of the quintic Bezier curve


@functools.cache
def _tables() -> dict[str, np.ndarray]:
    """The RGB tables (benchmarks/sunsky_data.py), float32 as Mitsuba's kernels read them, widened to float64."""
    with np.load(DATA) as f:
        return {k: f[k].astype(np.float64) for k in f.files}


def _along_turbidity(table: np.ndarray, turbidity: float) -> np.ndarray:
    """Linear interpolation over the tables' first axis, turbidity 1, 2, ..., 10 (Mitsuba's ``take_interp``)."""
    t = min(max(turbidity - 1.0, 0.0), table.shape[0] - 1.0)
    i = min(int(t), table.shape[0] - 2)
    f = t - i
    return table[i] * (1.0 - f) + table[i + 1] * f


def _bezier(control: np.ndarray, elevation: float) -> np.ndarray:
    """The quintic Bezier curve through the tables' six control points (axis 0) at the sun's elevation (radians),
    in x = (2 eta / pi)^(1/3), as the published model (and Mitsuba, which keeps x below 1)."""
    x = min(np.cbrt(2.0 * elevation / math.pi), 1.0 - 2.0**-24)
    return sum(_BEZIER[i] * x**i * (1.0 - x) ** (5 - i) * control[i] for i in range(6))


def sky_state(turbidity: float, albedo, elevation: float) -> tuple[np.ndarray, np.ndarray]:
    """The sky's nine parameters per channel (3, 9) and its radiance scale (3,) for a sun ``elevation`` radians up."""
    tables = _tables()
    a = np.broadcast_to(np.asarray(albedo, dtype=np.float64).reshape(-1), (3,))
    params = _along_turbidity(tables["sky_params"], turbidity)  # (2 albedos, 6, 3, 9)
    params = params[0] * (1.0 - a[None, :, None]) + params[1] * a[None, :, None]
    scale = _along_turbidity(tables["sky_radiance"], turbidity)  # (2, 6, 3)
    scale = scale[0] * (1.0 - a[None, :]) + scale[1] * a[None, :]
    return _bezier(params, elevation), _bezier(scale, elevation)


def _gamma(dirs: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Angle between unit directions and the sun, accurate near 0 (2 asin(|d - s| / 2), as Mitsuba's unit_angle)."""
    dot = dirs @ sun
    near = 2.0 * np.arcsin(np.minimum(1.0, np.linalg.norm(dirs - sun, axis=-1) / 2.0))
    far = math.pi - 2.0 * np.arcsin(np.minimum(1.0, np.linalg.norm(dirs + sun, axis=-1) / 2.0))
    return np.where(dot >= 0.0, near, far)


def sky_radiance(dirs, sun, params: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """RGB sky radiance (N, 3) arriving from unit world directions ``dirs`` (N, 3) for a sun toward unit ``sun``,
    with :func:`sky_state`'s parameters: the model of the module docstring, black below the horizon."""
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    cos_theta = d[:, 1]
    gamma = _gamma(d, np.asarray(sun, dtype=np.float64))
    cos_gamma = np.cos(gamma)[:, None]
    up = np.maximum(cos_theta, 0.0)[:, None]
    p = [params[None, :, i] for i in range(9)]
    c1 = 1.0 + p[0] * np.exp(p[1] / (up + 0.01))
    chi = (1.0 + cos_gamma**2) / (1.0 + p[8] ** 2 - 2.0 * p[8] * cos_gamma) ** 1.5
    c2 = p[2] + p[3] * np.exp(p[4] * gamma[:, None]) + p[5] * cos_gamma**2 + p[6] * chi + p[7] * np.sqrt(up)
    out = c1 * c2 * scale[None, :] * CIE_Y_NORMALIZATION
    return np.where((cos_theta >= 0.0)[:, None], out, 0.0)


def sun_table(turbidity: float) -> np.ndarray:
    """The sun's polynomial coefficients (45 segments, 3 channels, 4 powers of x, 6 powers of mu) at
    ``turbidity``."""
    return _along_turbidity(_tables()["sun_radiance"], turbidity)


def sun_scale_factor(aperture_deg: float, sun_scale: float = 1.0) -> float:
    """What the table's polynomial is multiplied by: ``sun_scale``, the ratio that keeps the irradiance of a disc
    of ``aperture_deg`` that of the standard sun, and Mitsuba's two RGB constants."""
    # Mitsuba computes the ratio in float32 (BaseSunskyEmitter::get_area_ratio), where 1 - cos of a quarter degree
    # keeps about two significant digits: its ratio is 1 for the standard aperture but 0.2 % low at 2 degrees
    # (measured: tests/data/mitsuba_sunsky_radiance.npz).  Computed the same way here, to give Mitsuba's radiance.
    f32 = np.float32
    half = f32(disc_angles(aperture_deg)[0])
    standard = f32(math.pi * (0.5 * SUN_APERTURE) / 180.0)
    ratio = float((f32(1.0) - np.cos(standard)) / (f32(1.0) - np.cos(half)))
    return sun_scale * ratio * SPEC_TO_RGB_SUN_CONV * CIE_Y_NORMALIZATION


def disc_angles(aperture_deg: float) -> tuple[float, float]:
    """(alpha, cos alpha) of a sun of angular diameter ``aperture_deg`` as Mitsuba's disc has them: alpha its float32
    ``deg_to_rad(0.5 aperture)``, and cos alpha rounded to float32, as Mitsuba computes it for its disc's edge, its
    cone sampling and its density.  Near 1, float32 keeps cos alpha to 6e-8, so Mitsuba's standard disc has
    1 - cos alpha 0.2 % below the exact one (1.0908e-5 for 1.0931e-5), and with it 0.2 % less of the sun's
    irradiance: with the exact disc, lightprobe's render of the sunsky reference scene was 0.09 % brighter than
    Mitsuba's (4.6 sigma at 1024 spp; decisions.md 109).  Kept, to give Mitsuba's sun."""
    f32 = np.float32
    alpha = f32(f32(0.5) * f32(aperture_deg)) * f32(math.pi / 180.0)
    return float(alpha), float(np.cos(alpha))


def sun_radiance(dirs, sun, turbidity: float, aperture_deg: float = SUN_APERTURE, sun_scale: float = 1.0):
    """RGB radiance (N, 3) of the limb-darkened sun seen along unit directions ``dirs`` (zero outside its disc of
    angular diameter ``aperture_deg`` and below the horizon): the reference the compiled kernel
    (:func:`lightprobe.emitters.sun.sun_disc_radiance`) is tested against."""
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    s = np.asarray(sun, dtype=np.float64)
    alpha, cos_alpha = disc_angles(aperture_deg)
    gamma = _gamma(d, s)
    inside = (d @ s >= cos_alpha) & (d[:, 1] >= 0.0)
    mu = np.sqrt(np.maximum(0.0, 1.0 - np.sin(gamma) ** 2 / math.sin(alpha) ** 2))
    eta = math.pi / 2.0 - np.arccos(np.clip(d[:, 1], -1.0, 1.0))
    segment = np.minimum(np.floor(np.cbrt(np.maximum(2.0 * eta / math.pi, 0.0)) * SUN_SEGMENTS), SUN_SEGMENTS - 1)
    segment = segment.astype(np.int64)
    x = eta - math.pi / 2.0 * (segment / SUN_SEGMENTS) ** 3
    table = sun_table(turbidity)[segment]  # (N, 3, 4, 6)
    powers = (x[:, None] ** np.arange(4))[:, :, None] * (mu[:, None] ** np.arange(6))[:, None, :]  # (N, 4, 6)
    out = np.einsum("nckj,nkj->nc", table, powers) * sun_scale_factor(aperture_deg, sun_scale)
    return np.where(inside[:, None], out, 0.0)


def uniform_sun_radiance(turbidity: float, elevation: float, aperture_deg: float = SUN_APERTURE,
                         sun_scale: float = 1.0) -> np.ndarray:  # fmt: skip
    """RGB radiance (3,) of Mitsuba's uniform sun (``complex_sun = false``), the same over its disc, for a sun
    ``elevation`` radians up: the sun's spectral irradiance (11 wavelengths) interpolated linearly in turbidity and
    over the 30 tabulated elevations 2, 5, ..., 89 degrees, averaged against Mitsuba's linear sRGB response (its
    ``spectrum_to_srgb``), over the solid angle of the standard 0.5358-degree disc (float32, as Mitsuba's), times
    :func:`sun_scale_factor`.  Mitsuba's documentation says its two suns give the same power; measured on its own
    values they do within 0.1-1 % with the sun 10 degrees up or more, but at 3 degrees and turbidity 10 the
    limb-darkened sun is 9 times dimmer (at 1 degree and turbidity 4, 3 times)."""
    tables = _tables()
    spectrum = _along_turbidity(tables["sun_irradiance"], turbidity)  # (30, 11)
    row = min(max((math.degrees(elevation) - 2.0) / 3.0, 0.0), spectrum.shape[0] - 1.0)
    i = min(int(row), spectrum.shape[0] - 2)
    spectrum = spectrum[i] * (1.0 - (row - i)) + spectrum[i + 1] * (row - i)
    rgb = (tables["rgb_response"] * spectrum[:, None]).mean(axis=0)
    f32 = np.float32
    solid_angle = 2.0 * math.pi * float(f32(1.0) - np.cos(f32(math.pi * (0.5 * SUN_APERTURE) / 180.0)))
    return rgb / solid_angle * sun_scale_factor(aperture_deg, sun_scale)


def latlong_directions(width: int, height: int) -> np.ndarray:
    """World directions (H, W, 3) of the nodes a lat-long map's bilinear lookup interpolates (Mitsuba's: column i
    at u = (i + 0.5) / W, row j at v = j / (H - 1); lightprobe.emitters.mappings)."""
    u = (np.arange(width) + 0.5) / width
    v = np.arange(height) / (height - 1)
    theta, phi = np.pi * v[:, None], 2.0 * np.pi * u[None, :]
    return np.stack(
        np.broadcast_arrays(np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)), axis=-1
    )


def sky_image(sun, params: np.ndarray, scale: np.ndarray, *, width: int, height: int) -> np.ndarray:
    """The sky as a lat-long image (H, W, 3) float32 whose bilinear lookup interpolates the model between its
    nodes (so every node is exact; the horizon is a node row when H is odd)."""
    d = latlong_directions(width, height).reshape(-1, 3)
    return sky_radiance(d, sun, params, scale).reshape(height, width, 3).astype(np.float32)


# Mitsuba's defaults for the time-and-place form (Tokyo, 10 July 2010, 15:00 local time)
PLACE_AND_TIME = {"year": 2010, "month": 7, "day": 10, "hour": 15.0, "minute": 0.0, "second": 0.0,
                  "latitude": 35.6894, "longitude": 139.6917, "timezone": 9.0}  # fmt: skip
EARTH_MEAN_RADIUS = 6371.01  # km
ASTRONOMICAL_UNIT = 149597890.0  # km


def _c_divide(a: int, b: int) -> int:
    """Integer division truncated toward zero, as C's (and Mitsuba's Int32) ``/``; Python's // floors."""
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b > 0) else -q


def sun_position(**when) -> np.ndarray:
    """The world direction toward the sun (Y up) at a date, time and place, as Mitsuba's: keys of
    :data:`PLACE_AND_TIME` (``year``, ``month``, ``day``, ``hour``, ``minute``, ``second`` of local time,
    ``latitude`` and ``longitude`` in degrees (north and east positive), ``timezone`` in hours from UTC; Mitsuba's
    defaults for the others).

    Blanco-Muriel et al. 2001, "Computing the Solar Vector" (Solar Energy 70(5)), as Mitsuba 3.9.1's
    ``BaseSunskyEmitter::sun_coordinates`` computes it, including its float32 Julian date (float32 holds a date of
    about 2.46e6 days to a quarter of a day, which moves the sun by up to about 0.2 degrees from the exact
    position; kept, to give Mitsuba's sun).  Frame, measured on Mitsuba's own sun directions with its sunsky stood
    on lightprobe's +Y (``to_world`` -90 degrees about +X; its documentation calls its local +X north): the
    northern hemisphere's noon sun stands toward +X, the morning sun toward +Z, the evening sun toward -Z (Tokyo,
    10 July 2010: 10:00 (0.17, 0.89, 0.41), 15:00 (0.05, 0.72, -0.69)).
    """
    unknown = set(when) - set(PLACE_AND_TIME)
    if unknown:
        raise ParameterError(f"sunsky: unknown time or place key(s) {', '.join(sorted(unknown))}")
    t = {**PLACE_AND_TIME, **when}
    for key in ("year", "month", "day"):
        if isinstance(t[key], bool) or not isinstance(t[key], numbers.Integral):
            raise ParameterError(f"sunsky: {key} must be an integer, got {t[key]!r}")
    if not 1 <= t["month"] <= 12 or not 1 <= t["day"] <= 31:
        raise ParameterError(f"sunsky: month must be 1-12 and day 1-31, got {t['month']!r} and {t['day']!r}")
    _number(t["latitude"], "latitude", -90.0, 90.0, " degrees")
    _number(t["longitude"], "longitude", -360.0, 360.0, " degrees")
    _number(t["timezone"], "timezone", -24.0, 24.0, " hours")
    for key in ("hour", "minute", "second"):
        _number(t[key], key, -1e6, 1e6)
    year, month, day = int(t["year"]), int(t["month"]), int(t["day"])
    f32 = np.float32
    dec_hours = t["hour"] - t["timezone"] + (t["minute"] + t["second"] / 60.0) / 60.0
    aux1 = _c_divide(month - 14, 12)
    aux2 = (
        _c_divide(1461 * (year + 4800 + aux1), 4)
        + _c_divide(367 * (month - 2 - 12 * aux1), 12)
        - _c_divide(3 * _c_divide(year + 4900 + aux1, 100), 4)
        + day
        - 32075
    )
    julian_date = f32(f32(f32(aux2) - f32(0.5)) + f32(dec_hours / 24.0))  # float32, as Mitsuba's Float
    days = float(f32(julian_date - f32(2451545.0)))
    # ecliptic coordinates (radians)
    omega = 2.1429 - 0.0010394594 * days
    mean_longitude = 4.8950630 + 0.017202791698 * days
    anomaly = 6.2400600 + 0.0172019699 * days
    ecliptic_longitude = (mean_longitude + 0.03341607 * math.sin(anomaly) + 0.00034894 * math.sin(2 * anomaly)
                          - 0.0001134 - 0.0000203 * math.sin(omega))  # fmt: skip
    obliquity = 0.4090928 - 6.2140e-9 * days + 0.0000396 * math.cos(omega)
    # celestial coordinates
    sin_longitude = math.sin(ecliptic_longitude)
    right_ascension = math.atan2(math.cos(obliquity) * sin_longitude, math.cos(ecliptic_longitude))
    if right_ascension < 0.0:
        right_ascension += 2.0 * math.pi
    declination = math.asin(math.sin(obliquity) * sin_longitude)
    # local coordinates: zenith angle and azimuth
    sidereal = math.radians((6.6974243242 + 0.0657098283 * days + dec_hours) * 15.0 + t["longitude"])
    latitude = math.radians(t["latitude"])
    hour_angle = sidereal - right_ascension
    zenith = math.acos(math.cos(latitude) * math.cos(hour_angle) * math.cos(declination)
                       + math.sin(declination) * math.sin(latitude))  # fmt: skip
    toward_north = math.tan(declination) * math.cos(latitude) - math.sin(latitude) * math.cos(hour_angle)
    azimuth = math.atan2(-math.sin(hour_angle), toward_north)
    if azimuth < 0.0:
        azimuth += 2.0 * math.pi
    zenith += EARTH_MEAN_RADIUS / ASTRONOMICAL_UNIT * math.sin(zenith)  # parallax
    phi = azimuth - math.pi
    # Mitsuba's sph_to_dir(zenith, phi) in its Z-up frame, turned onto lightprobe's Y up: (x, y, z) -> (x, z, -y)
    return np.array([math.sin(zenith) * math.cos(phi), math.cos(zenith), -math.sin(zenith) * math.sin(phi)])


def _describe_when(when: dict) -> str:
    """The date, local time (hh:mm:ss of hour + minute + second) and place, for a message."""
    t = {**PLACE_AND_TIME, **when}
    seconds = round(3600.0 * t["hour"] + 60.0 * t["minute"] + t["second"])
    clock = f"{seconds // 3600:02d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"
    return (
        f"{t['year']:04d}-{t['month']:02d}-{t['day']:02d} {clock} (UTC{t['timezone']:+g}), "
        f"latitude {t['latitude']:g}, longitude {t['longitude']:g}"
    )


def _number(value, name: str, lo: float, hi: float, unit: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not lo <= float(value) <= hi:
        raise ParameterError(f"sunsky: {name} must be a number from {lo:g} to {hi:g}{unit}, got {value!r}")
    return float(value)
