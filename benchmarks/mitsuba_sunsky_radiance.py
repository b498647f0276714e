#!/usr/bin/env python3
"""Mitsuba 3.9.1's ``sunsky`` radiance at chosen directions: ``tests/data/mitsuba_sunsky_radiance.npz``.

    python benchmarks/mitsuba_sunsky_radiance.py      # needs Mitsuba 3.9.1 (pip install -e '.[peers]')

For each setting of :data:`SETTINGS` (turbidity, ground albedo, the sun's elevation and lat-long azimuth in degrees,
the sun's aperture), Mitsuba's ``sunsky`` emitter (variant ``llvm_ad_rgb``, ``complex_sun = true``: the
limb-darkened sun, ``to_world`` = a -90 degree rotation about +X so that its Z-up sky stands on lightprobe's +Y,
``sun_direction`` the world direction of ``lightprobe.emitters.procedural.sun_direction``) is evaluated
(``emitter.eval`` with ``si.wi = -direction``) with ``sun_scale = 0`` (the sky alone) at ``SKY_DIRECTIONS`` directions
(uniform on the sphere, some below the horizon, plus rings 0.5-20 degrees around the sun) and with ``sky_scale = 0``
(the sun alone) at points of the sun's disc (its centre and rings at 0.2-0.95 of its radius), also with
``complex_sun = false`` (Mitsuba's default uniform sun, ``sun_uniform``); and for each date,
time and place of :data:`PLACES_AND_TIMES`, the world direction of Mitsuba's sun (its read-only ``sun_direction``).
The tests (tests/emitters/test_sunsky.py) compare lightprobe's sky and sun with these values; they need no Mitsuba.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

# turbidity, albedo (a number or RGB), sun elevation, sun azimuth, sun aperture (degrees)
SETTINGS = (
    (3.0, 0.3, 35.0, 60.0, 0.5358),
    (1.0, 0.0, 10.0, 200.0, 0.5358),
    (6.5, 0.8, 62.0, 0.0, 0.5358),
    (10.0, (0.1, 0.5, 0.9), 3.0, 120.0, 0.5358),
    (2.2, 0.5, 84.0, 300.0, 2.0),
)
# dates, times and places (Mitsuba's keys; the others its defaults): its sun's world direction for each
PLACES_AND_TIMES = (
    {"hour": 10.0},
    {"hour": 15.0},
    {"year": 2024, "month": 1, "day": 3, "hour": 9.25, "latitude": -33.9, "longitude": 18.4, "timezone": 2.0},
    {"year": 1999, "month": 12, "day": 31, "hour": 23.5, "minute": 30.0, "latitude": 64.1, "longitude": -21.9,
     "timezone": 0.0},
    {"year": 2031, "month": 3, "day": 20, "hour": 12.0, "second": 30.0, "latitude": 0.0, "longitude": -78.5,
     "timezone": -5.0},
    {"year": 2026, "month": 6, "day": 21, "hour": 17.75, "latitude": 51.5, "longitude": -0.1, "timezone": 1.0},
)  # fmt: skip
SKY_DIRECTIONS = 240
SUN_RINGS = (0.0, 0.2, 0.5, 0.8, 0.95)
SUN_RING_POINTS = 8


def _ring(axis: np.ndarray, angles_deg, points: int) -> np.ndarray:
    """Directions at the given angles from ``axis``, ``points`` around each ring (one for angle 0)."""
    t = np.cross(axis, [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 else [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    out = []
    for a in np.radians(angles_deg):
        n = 1 if a == 0.0 else points
        for k in range(n):
            phi = 2.0 * np.pi * (k + 0.25) / n
            out.append(np.cos(a) * axis + np.sin(a) * (np.cos(phi) * t + np.sin(phi) * b))
    return np.array(out)


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """lightprobe.emitters.procedural.sun_direction, written out: Mitsuba's environment has no Numba to import
    lightprobe with (the tests check that the two agree, from the directions stored)."""
    theta, phi = np.radians(90.0 - elevation_deg), np.radians(azimuth_deg)
    return np.array([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)])


def main() -> int:
    from mitsuba_references import _prefer_llvm19

    _prefer_llvm19()
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    rng = np.random.default_rng(58)
    settings, sky_dirs, sky, sun_dirs, sun, uniform = [], [], [], [], [], []
    for turbidity, albedo, elevation, azimuth, aperture in SETTINGS:
        d_sun = sun_direction(elevation, azimuth)
        z = rng.normal(size=(SKY_DIRECTIONS, 3))
        z /= np.linalg.norm(z, axis=1, keepdims=True)
        dirs = np.concatenate([z, _ring(d_sun, [0.5, 1.0, 2.0, 5.0, 10.0, 20.0], 6)])
        disc = _ring(d_sun, np.array(SUN_RINGS) * aperture / 2.0, SUN_RING_POINTS)

        def emitter(sun_scale, sky_scale, turbidity=turbidity, albedo=albedo, aperture=aperture, d_sun=d_sun,
                    complex_sun=True):  # fmt: skip
            a = {"type": "rgb", "value": list(map(float, albedo))} if isinstance(albedo, tuple) else float(albedo)
            return mi.load_dict({
                "type": "sunsky", "turbidity": float(turbidity), "albedo": a, "sun_aperture": float(aperture),
                "sun_direction": mi.ScalarVector3f(*map(float, d_sun)), "complex_sun": complex_sun,
                "sun_scale": float(sun_scale), "sky_scale": float(sky_scale),
                "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90),
            })  # fmt: skip

        def evaluate(em, d):
            si = dr.zeros(mi.SurfaceInteraction3f, d.shape[0])
            si.wi = mi.Vector3f(*(-d.T.astype(np.float32)))
            return np.array(em.eval(si), dtype=np.float64).T.reshape(-1, 3)

        sky_dirs.append(dirs)
        sky.append(evaluate(emitter(0.0, 1.0), dirs))
        sun_dirs.append(disc)
        sun.append(evaluate(emitter(1.0, 0.0), disc))
        uniform.append(evaluate(emitter(1.0, 0.0, complex_sun=False), disc))
        settings.append(
            {"turbidity": turbidity, "albedo": albedo, "sun_elevation": elevation, "sun_azimuth": azimuth,
             "sun_aperture": aperture, "sun_direction": d_sun.tolist()}
        )  # fmt: skip
    positions = []
    for when in PLACES_AND_TIMES:
        keys = {k: (int(v) if k in ("year", "month", "day") else float(v)) for k, v in when.items()}
        em = mi.load_dict({"type": "sunsky", **keys, "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90)})
        positions.append(np.array(mi.traverse(em)["sun_direction"], dtype=np.float64).ravel())
    out = ROOT / "tests" / "data" / "mitsuba_sunsky_radiance.npz"
    record = {"mitsuba": mi.__version__, "variant": mi.variant(), "complex_sun": {"sun": True, "sun_uniform": False},
              "settings": settings, "places_and_times": list(PLACES_AND_TIMES)}  # fmt: skip
    np.savez_compressed(
        out,
        settings=json.dumps(record),
        sky_directions=np.array(sky_dirs, np.float32),
        sky=np.array(sky, np.float32),
        sun_directions=np.array(sun_dirs, np.float32),
        sun=np.array(sun, np.float32),
        sun_positions=np.array(positions, np.float32),
        sun_uniform=np.array(uniform, np.float32),
    )
    print(out, out.stat().st_size, "bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
