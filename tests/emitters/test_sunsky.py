"""The Hosek-Wilkie sun and sky (emitters/hosek_wilkie.py, sun.py, sunsky.py) against Mitsuba 3.9.1's ``sunsky``.

``tests/data/mitsuba_sunsky_radiance.npz`` (made by benchmarks/mitsuba_sunsky_radiance.py, without which these
tests need no Mitsuba) holds Mitsuba's radiance of five settings (turbidity 1-10, albedo 0-1 and one RGB albedo,
the sun 3-84 degrees up, apertures 0.5358 and 2 degrees): the sky alone at 276 directions each, a fifth of them
below the horizon, and the sun alone at 33 points of its disc.  Then the sun's sampler against its own density, the
baked sky map against the model, and the errors of bad parameters.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from lightprobe.analysis import chi2
from lightprobe.emitters.hosek_wilkie import sky_radiance, sun_position
from lightprobe.emitters.lights import escaped_batch, light_arrays, pdf_batch, sample_batch
from lightprobe.emitters.procedural import sun_direction
from lightprobe.emitters.sun import SunLight
from lightprobe.emitters.sunsky import SunSky
from lightprobe.errors import ParameterError
from lightprobe.geometry.frame import frame_matrix

DATA = Path(__file__).resolve().parents[1] / "data" / "mitsuba_sunsky_radiance.npz"
NORMAL = np.array([0.0, 1.0, 0.0])


def _reference():
    with np.load(DATA) as f:
        meta = json.loads(str(f["settings"]))
        keys = ("sky_directions", "sky", "sun_directions", "sun", "sun_positions", "sun_uniform")
        arrays = {k: f[k].astype(np.float64) for k in keys}
    return meta, arrays


def _sunsky(setting: dict, **options) -> SunSky:
    return SunSky(
        **options,
        turbidity=setting["turbidity"],
        albedo=setting["albedo"],
        sun_elevation=setting["sun_elevation"],
        sun_azimuth=setting["sun_azimuth"],
        sun_aperture=setting["sun_aperture"],
    )


def test_the_reference_is_mitsubas_limb_darkened_sunsky_in_our_frame():
    """The data are what they say: Mitsuba 3.9.1's RGB variant with the limb-darkened sun, and its sun stands where
    lightprobe's elevation and azimuth put it."""
    meta, _ = _reference()
    assert meta["mitsuba"] == "3.9.1" and "rgb" in meta["variant"]
    assert meta["complex_sun"] == {"sun": True, "sun_uniform": False}
    for s in meta["settings"]:
        np.testing.assert_allclose(sun_direction(s["sun_elevation"], s["sun_azimuth"]), s["sun_direction"], atol=1e-15)


def test_the_sky_is_mitsubas():
    """Every direction of every setting: black exactly where Mitsuba's is (below the horizon), elsewhere within
    2e-5 relative (measured at most 4.2e-6: Mitsuba evaluates in float32, these in float64)."""
    meta, ref = _reference()
    for i, s in enumerate(meta["settings"]):
        sky = _sunsky(s)
        ours = sky_radiance(ref["sky_directions"][i], sky.direction, sky.params, sky.scale)
        theirs = ref["sky"][i]
        assert np.array_equal(ours == 0.0, theirs == 0.0), s
        lit = theirs != 0.0
        assert lit.sum() > 150
        np.testing.assert_allclose(ours[lit], theirs[lit], rtol=2e-5, err_msg=str(s))


def test_the_suns_disc_is_mitsubas():
    """The sun's compiled radiance (through the light contract: what a ray escaping along a direction sees) at its
    centre and on rings to 0.95 of its radius, every setting: within 1e-3 of the point's brightest channel
    (measured at most 1.4e-4: Mitsuba's float32 limb cosine near the rim; a sun 3 degrees up at turbidity 10 has a
    blue channel near 0, so the error is scaled by the point's brightest channel), and, 10 degrees up or more,
    darker at the limb."""
    meta, ref = _reference()
    for i, s in enumerate(meta["settings"]):
        sun = _sunsky(s).sun()
        dirs = ref["sun_directions"][i]
        ours = escaped_batch(light_arrays([sun]), dirs)
        theirs = ref["sun"][i]
        scale = np.abs(theirs).max(axis=1, keepdims=True)
        assert np.all(np.abs(ours - theirs) <= 1e-3 * scale), (s, np.max(np.abs(ours - theirs) / scale))
        np.testing.assert_allclose(sun.radiance_at(dirs), ours, rtol=1e-9, atol=1e-9 * scale.max())
        centre, rim = ours[0], ours[-8:]  # the last ring is at 0.95 of the radius
        if s["sun_elevation"] >= 10.0:  # lower, the sun's fall toward the horizon outweighs its limb darkening
            assert np.all(rim.sum(axis=1) < 0.8 * centre.sum()), s


def test_the_uniform_sun_is_mitsubas():
    """Mitsuba's default sun (``complex_sun = false``): the same radiance over the disc, from the sun's spectral
    irradiance table through Mitsuba's RGB response, within 1e-5 of the point's brightest channel (measured 4e-6),
    black outside the horizon's side; in every setting it differs from the limb-darkened sun's mean (Mitsuba's two
    suns are not the same light: 9x apart at 3 degrees, turbidity 10)."""
    meta, ref = _reference()
    for i, s in enumerate(meta["settings"]):
        sun = _sunsky(s, limb_darkening=False).sun()
        ours = escaped_batch(light_arrays([sun]), ref["sun_directions"][i])
        theirs = ref["sun_uniform"][i]
        scale = np.abs(theirs).max(axis=1, keepdims=True)
        assert np.all(np.abs(ours - theirs) <= 1e-5 * scale), (s, np.max(np.abs(ours - theirs) / scale))
        np.testing.assert_allclose(ours, np.broadcast_to(sun.radiance, ours.shape), rtol=1e-12)
        assert not np.allclose(sun.radiance, _sunsky(s).sun().radiance, rtol=1e-3)


def test_the_suns_mean_radiance_gives_its_irradiance():
    """The row's radiance (the disc's mean, which the light selector turns into the sun's irradiance) is the mean
    of the disc's radiance over uniform samples of the cone."""
    sun = SunLight(sun_direction(35.0, 60.0), turbidity=3.0)
    n = 100_000
    u = np.random.default_rng(5).random((n, 2))
    out = sample_batch(light_arrays([sun]), 0, np.zeros((n, 3)), np.tile(NORMAL, (n, 1)), u)
    np.testing.assert_allclose(out[:, 4:7].mean(axis=0), sun.radiance, rtol=2e-3)


@pytest.mark.parametrize(
    ("elevation", "aperture", "limb_darkening"), [(35.0, 0.5358, True), (2.0, 0.5358, True), (50.0, 8.0, False)]
)
def test_the_suns_samples_match_its_pdf(elevation, aperture, limb_darkening):
    """Chi-square of the sun's samples against its own pdf (rings inside the cone, the last a hair past its rim,
    then the rest of the sphere), the pdf integrating to 1 over the sphere, and every sample's density equal to
    pdf() at its direction; the radiance of every sample is the disc's there."""
    sun = SunLight(sun_direction(elevation, 30.0), turbidity=4.0, aperture=aperture, limb_darkening=limb_darkening)
    table = light_arrays([sun])
    n = 200_000
    out = sample_batch(table, 0, np.zeros((n, 3)), np.tile(NORMAL, (n, 1)), np.random.default_rng(17).random((n, 2)))

    def density(v):
        return pdf_batch(table, 0, np.zeros((v.shape[0], 3)), np.tile(NORMAL, (v.shape[0], 1)), v)

    rim = math.radians(aperture) / 2 * (1 + 1e-6)
    edges = np.concatenate([np.linspace(0.0, rim, 49), np.linspace(rim, math.pi, 17)[1:]])
    result = chi2.spherical_test(
        out[:, :3],
        density,
        frame=frame_matrix(sun.sun_direction),
        theta_edges=edges,
        phi_edges=np.linspace(0, 2 * np.pi, 65),
        test_count=3,
    )
    assert result.passed, str(result)
    assert result.pdf_integral == pytest.approx(1.0, abs=2e-3)
    np.testing.assert_allclose(density(out[:, :3]), out[:, 7], rtol=1e-12)
    np.testing.assert_allclose(out[:, 7], 1.0 / sun.solid_angle, rtol=1e-9)
    np.testing.assert_allclose(out[:, 4:7], sun.radiance_at(out[:, :3]), rtol=1e-9, atol=1e-9 * sun.radiance.max())
    assert np.all(np.isinf(out[:, 3])) and np.all(out[:, 8] == 0.0)


def test_a_sun_pdf_of_the_wrong_aperture_fails_the_chi_square_test():
    """Negative control: the samples of a 5-degree sun against the density of a 5.5-degree one."""
    narrow = light_arrays([SunLight(sun_direction(40.0, 0.0), aperture=5.0)])
    wide = light_arrays([SunLight(sun_direction(40.0, 0.0), aperture=5.5)])
    n = 200_000
    out = sample_batch(narrow, 0, np.zeros((n, 3)), np.tile(NORMAL, (n, 1)), np.random.default_rng(3).random((n, 2)))

    def density(v):
        return pdf_batch(wide, 0, np.zeros((v.shape[0], 3)), np.tile(NORMAL, (v.shape[0], 1)), v)

    rim = math.radians(5.5) / 2 * (1 + 1e-6)
    edges = np.concatenate([np.linspace(0.0, rim, 49), np.linspace(rim, math.pi, 17)[1:]])
    frame = frame_matrix(sun_direction(40.0, 0.0))
    assert not chi2.spherical_test(out[:, :3], density, frame=frame, theta_edges=edges).passed


@pytest.mark.parametrize(("turbidity", "elevation"), [(3.0, 35.0), (10.0, 3.0)])
def test_the_baked_sky_map_is_the_model(turbidity, elevation):
    """The environment map of the default width (1024 x 513, the horizon a row of nodes) looked up bilinearly,
    against the model at 100,000 random directions above the horizon: mean relative error under 1e-4 and at most
    5e-3 (measured 3.4e-5 and 1.0e-3 at 3 x 35 degrees, 3.5e-5 and 3.2e-3 at 10 x 3 degrees, the worst near the
    horizon and the sun); black below the horizon."""
    sky = SunSky(turbidity=turbidity, sun_elevation=elevation, sun_azimuth=60.0)
    env = sky.environment()
    rng = np.random.default_rng(23)
    d = rng.normal(size=(120_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    up = d[d[:, 1] > 0.02][:100_000]
    model = np.maximum(sky_radiance(up, sky.direction, sky.params, sky.scale), 0.0)
    relative = np.abs(env.eval(up) - model) / np.maximum(model, 1e-3 * model.max())
    assert relative.mean() < 1e-4 and relative.max() < 5e-3, (relative.mean(), relative.max())
    down = d[d[:, 1] < -0.01]
    assert np.all(env.eval(down) == 0.0)


def test_the_scales_and_the_aperture_scale_the_two_parts():
    """sky_scale multiplies the map; sun_scale the sun; a wider aperture keeps the sun's irradiance (its mean
    radiance times its solid angle) within Mitsuba's float32 ratio's 0.3 %; a scale of 0 leaves that part out."""
    base = SunSky(turbidity=3.0, sun_elevation=40.0)
    twice = SunSky(turbidity=3.0, sun_elevation=40.0, sun_scale=2.0, sky_scale=3.0)
    np.testing.assert_allclose(twice.sky_image(64), 3.0 * base.sky_image(64), rtol=1e-6)
    np.testing.assert_allclose(twice.sun().radiance, 2.0 * base.sun().radiance, rtol=1e-12)
    wide = SunSky(turbidity=3.0, sun_elevation=40.0, sun_aperture=3.0).sun()
    e_base = base.sun().radiance * base.sun().solid_angle
    np.testing.assert_allclose(wide.radiance * wide.solid_angle, e_base, rtol=3e-3)
    assert SunSky(sun_elevation=40.0, sun_scale=0.0).sun() is None
    assert SunSky(sun_elevation=40.0, sky_scale=0.0).environment() is None


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"turbidity": 0.5}, "turbidity must be a number from 1 to 10"),
        ({"turbidity": 11}, "turbidity must be a number from 1 to 10"),
        ({"turbidity": "hazy"}, "turbidity"),
        ({"albedo": 1.5}, "albedo must be a number or"),
        ({"albedo": [0.1, 0.2]}, "albedo"),
        ({"sun_elevation": -5.0}, "below the horizon"),
        ({"sun_elevation": 95.0}, "sun_elevation must be a number from 0 to 90"),
        ({"sun_direction": [0.3, -1.0, 0.0]}, "below the horizon"),
        ({"sun_direction": [0.0, 0.0, 0.0]}, "sun_direction must be 3 finite numbers"),
        ({"sun_direction": [0.0, 1.0, 0.0], "sun_elevation": 30.0}, "not both"),
        ({"sun_scale": 0.0, "sky_scale": 0.0}, "nothing would emit"),
        ({"sky_scale": -1.0}, "sky_scale"),
        ({"sun_aperture": 0.0}, "sun_aperture must be in"),
        ({"sun_aperture": 90.0}, "sun_aperture must be in"),
        ({"sun_azimuth": math.nan}, "sun_azimuth"),
        ({"limb_darkening": 1}, "limb_darkening must be true or false"),
    ],
)
def test_bad_parameters_are_one_clear_error(options, message):
    with pytest.raises(ParameterError, match=message) as info:
        SunSky(**options)
    assert "\n" not in str(info.value) and str(info.value).startswith("sunsky: ")


@pytest.mark.parametrize("compensated", [False, True])
def test_the_sky_maps_samples_match_its_pdf(compensated):
    """The sky's map (its odd height: the horizon a row of nodes; black below it; a circumsolar peak) through the
    environment map's own chi-square check, plain and MIS-compensated, its pdf integrating to 1, and every sample's
    density equal to pdf() at its direction."""
    env = SunSky(turbidity=2.0, sun_elevation=20.0, sun_azimuth=250.0).environment()
    assert env.resolution == (1024, 513)
    result = chi2.check_envmap_sampling(env, compensated=compensated, test_count=2)
    assert result.passed, str(result)
    assert result.pdf_integral == pytest.approx(1.0, abs=1e-4)
    dirs, pdf = env.sample(np.random.default_rng(9).random((50_000, 2)), compensated=compensated)
    assert np.all(dirs[:, 1] >= -0.01)  # nothing from below the horizon but the blend of its one row
    np.testing.assert_allclose(env.pdf(dirs, compensated=compensated), pdf, rtol=1e-9)


def test_the_sun_stands_where_mitsuba_puts_it_at_a_date_time_and_place():
    """Six dates, times and places (Mitsuba's defaults, the southern and northern hemispheres, the equator, a sun
    below the horizon, day boundaries and time zones): within 0.01 degrees of Mitsuba's sun (measured at most
    0.0015: its float32 trigonometry; both round the Julian date to float32 alike), and a sun below the horizon is
    one clear error."""
    meta, ref = _reference()
    for when, theirs in zip(meta["places_and_times"], ref["sun_positions"], strict=True):
        ours = sun_position(**when)
        assert np.linalg.norm(ours) == pytest.approx(1.0, abs=1e-12)
        angle = math.degrees(math.acos(min(1.0, float(ours @ theirs / np.linalg.norm(theirs)))))
        assert angle < 0.01, (when, angle)
        if theirs[1] < 0.0:
            with pytest.raises(ParameterError, match="the sun is below the horizon at 1999-12-31 24:00:00"):
                SunSky(when=when)
        else:
            np.testing.assert_allclose(SunSky(when=when).direction, ours, atol=1e-15)


@pytest.mark.parametrize(
    ("when", "message"),
    [
        ({"month": 13}, "month must be 1-12"),
        ({"year": 2010.5}, "year must be an integer"),
        ({"latitude": 95.0}, "latitude must be a number from -90 to 90"),
        ({"hour": "noon"}, "hour must be a number"),
        ({"date": "2010-07-10"}, "unknown time or place key"),
    ],
)
def test_bad_dates_and_places_are_one_clear_error(when, message):
    with pytest.raises(ParameterError, match=message) as info:
        SunSky(when=when)
    assert "\n" not in str(info.value)
    with pytest.raises(ParameterError, match="not both"):
        SunSky(when={"hour": 12.0}, sun_elevation=30.0)
