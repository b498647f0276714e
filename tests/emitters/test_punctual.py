"""Point and spot lights: their one direction, the radiance I / d^2 it brings, a density of 0 for every given
direction, their power, and clear errors for bad parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.emitters.area import STRATEGIES
from lightprobe.emitters.lights import light_arrays, pdf_batch, sample_batch
from lightprobe.emitters.punctual import PointLight, SpotLight
from lightprobe.emitters.selection import power_of_lights
from lightprobe.errors import ParameterError

RNG = np.random.default_rng(5)
POINTS = RNG.uniform(-2, 2, (64, 3)) * [1, 0, 1]
NORMALS = np.tile([0.0, 1.0, 0.0], (64, 1))


def _sample(light, strategy="solid-angle"):
    table = light_arrays([light])
    u = RNG.random((POINTS.shape[0], 2))
    return sample_batch(table, 0, POINTS, NORMALS, u, strategy=strategy)


@pytest.mark.parametrize("strategy", list(STRATEGIES))
def test_a_point_light_is_one_direction_with_the_inverse_square_law(strategy):
    light = PointLight([0.3, 2.0, -0.4], [5.0, 4.0, 3.0])
    out = _sample(light, strategy)  # every strategy: a delta light has one direction
    to_light = light.position - POINTS
    dist = np.linalg.norm(to_light, axis=1)
    np.testing.assert_allclose(out[:, :3], to_light / dist[:, None], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:, 3], dist, rtol=1e-12)
    np.testing.assert_allclose(out[:, 4:7], light.radiance / dist[:, None] ** 2, rtol=1e-12)
    assert np.all(out[:, 7] == 1.0) and np.all(out[:, 8] == 1.0)  # pdf 1, a delta light
    # no direction given in advance is ever the light's: density 0, so BSDF samples never weigh against it
    pdf = pdf_batch(light_arrays([light]), 0, POINTS, NORMALS, out[:, :3].copy(), strategy=strategy)
    assert np.all(pdf == 0.0)


def test_a_spot_light_falls_off_smoothly_between_its_angles():
    spot = SpotLight([0.0, 3.0, 0.0], [0.0, 0.0, 0.0], 10.0, cone_angle=40.0, falloff_start=20.0)
    table = light_arrays([spot])
    for angle, expected in [(0.0, 1.0), (19.0, 1.0), (30.0, None), (41.0, 0.0), (80.0, 0.0)]:
        x = 3.0 * math.tan(math.radians(angle))
        out = sample_batch(table, 0, np.array([[x, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), np.zeros((1, 2)))
        d2 = 9.0 + x * x
        if expected is None:  # the smoothstep of pbrt-v4 at the middle of the band: 0.5
            c = math.cos(math.radians(angle))
            t = (c - math.cos(math.radians(40))) / (math.cos(math.radians(20)) - math.cos(math.radians(40)))
            expected = t * t * (3 - 2 * t)
            assert 0.3 < expected < 0.7
        assert out[0, 4] == pytest.approx(10.0 * expected / d2, rel=1e-12, abs=1e-15), angle


def test_powers_are_the_integrals_of_the_intensity():
    point = PointLight([0, 0, 0], 2.0)
    spot = SpotLight([0, 0, 0], [0, -1, 0], 2.0, cone_angle=35.0, falloff_start=15.0)
    # numerically: 2 pi x the integral of I falloff(cos) over cos in [-1, 1]
    table = light_arrays([spot])
    c = np.linspace(-1, 1, 200_001)
    dirs = np.column_stack([np.sqrt(1 - c**2), -c, np.zeros_like(c)])  # angle acos(c) from the axis (0, -1, 0)
    out = sample_batch(table, 0, -dirs, np.tile([0.0, 1.0, 0.0], (c.size, 1)), np.zeros((c.size, 2)))
    intensity = out[:, 4]  # at distance 1
    numeric = 2 * math.pi * np.trapezoid(intensity, c)
    assert spot.power == pytest.approx(numeric, rel=1e-6)
    assert point.power == pytest.approx(4 * math.pi * 2.0)
    np.testing.assert_allclose(power_of_lights(light_arrays([point, spot])), [point.power, spot.power], rtol=1e-12)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: PointLight([0, 0], 1.0), "position"),
        (lambda: PointLight([0, 0, math.nan], 1.0), "position"),
        (lambda: PointLight([0, 0, 0], -1.0), "intensity"),
        (lambda: SpotLight([0, 0, 0], [0, 0, 0], 1.0), "target"),
        (lambda: SpotLight([0, 0, 0], [0, 1, 0], 1.0, cone_angle=120.0), "cone_angle"),
        (lambda: SpotLight([0, 0, 0], [0, 1, 0], 1.0, cone_angle=20.0, falloff_start=30.0), "falloff_start"),
    ],
)
def test_bad_parameters_name_themselves(make, message):
    with pytest.raises(ParameterError, match=message):
        make()
