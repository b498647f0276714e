"""Light selectors: every pmf sums to one, matches the frequencies of its picks, and select() reports pmf()."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from lightprobe.demo import light_panels
from lightprobe.emitters.area import AreaLight, light_arrays
from lightprobe.emitters.selection import SELECTORS, LightSampler


def _lights(n_panels: int = 300):
    """Triangles of powers over four decades, two spheres and two rectangles (one two-sided)."""
    from lightprobe.geometry.mesh import TriangleMesh
    from lightprobe.geometry.scene import _triangle_lights

    v, f, radiance = light_panels(n_panels, seed=3)
    mesh = TriangleMesh.from_arrays(v, f, smooth=False)
    tris = _triangle_lights(mesh, radiance, False)
    others = light_arrays(
        [
            AreaLight.sphere([2.0, 1.0, 0.0], 0.3, 20.0),
            AreaLight.sphere([-2.0, 0.5, 1.0], 0.1, 500.0),
            AreaLight.rectangle([-1, 3, -1], [2, 0, 0], [0, 0, 2], 5.0),
            AreaLight.rectangle([1, 1, 2], [0, 1, 0], [1, 0, 0], 8.0, two_sided=True),
        ]
    )
    return type(tris)(*(np.concatenate([getattr(tris, k), getattr(others, k)]) for k in tris._fields))


LIGHTS = _lights()
RECEIVERS = [
    ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
    ([2.5, 1.0, -1.0], [-0.6, 0.8, 0.0]),
    ([0.0, 5.0, 0.0], [0.0, -1.0, 0.0]),
    ([30.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
]


@pytest.mark.parametrize("env_power", [None, 40.0])
@pytest.mark.parametrize("mode", list(SELECTORS))
def test_pmf_sums_to_one_and_matches_the_picks(mode, env_power):
    sampler = LightSampler(mode, LIGHTS, env_power=env_power)
    n = LIGHTS.kind.shape[0] + (env_power is not None)
    for i, (p, nrm) in enumerate(RECEIVERS):
        pmf = sampler.pmf(p, nrm)
        assert pmf.shape == (n,) and np.all(pmf >= 0)
        assert pmf.sum() == pytest.approx(1.0, abs=1e-12), (mode, i, pmf.sum())
        samples = 400_000
        u = np.random.default_rng(100 + i).random(samples)
        light, reported = sampler.select(p, nrm, u)
        assert np.all(light >= 0)
        np.testing.assert_allclose(reported, pmf[light], rtol=1e-12)
        counts = np.bincount(light, minlength=n)
        # chi-square of the pick counts against the pmf, cells with fewer than 5 expected pooled
        expected = samples * pmf
        big = expected >= 5
        observed = np.append(counts[big], counts[~big].sum())
        wanted = np.append(expected[big], expected[~big].sum())
        keep = wanted > 0
        _, p_value = stats.chisquare(observed[keep], wanted[keep] * observed[keep].sum() / wanted[keep].sum())
        assert p_value > 0.01 / (3 * 2 * len(RECEIVERS)), (mode, i, p_value)
        assert counts[pmf == 0].sum() == 0


def test_power_selection_is_proportional_to_power_and_uniform_is_uniform():
    from lightprobe.emitters.selection import power_of_lights

    power = power_of_lights(LIGHTS)
    p = LightSampler("power", LIGHTS).pmf([0, 0, 0], [0, 1, 0])
    np.testing.assert_allclose(p, power / power.sum(), rtol=1e-9)  # differences of a CDF
    u = LightSampler("uniform", LIGHTS, env_power=1.0).pmf([0, 0, 0], [0, 1, 0])
    np.testing.assert_allclose(u, 1.0 / (LIGHTS.kind.shape[0] + 1))


def test_bvh_prefers_near_lights_and_skips_lights_facing_away():
    """Three equal lights over a receiver: near and facing it, near and facing away, far and facing it.  Power
    selection picks each with 1/3; the BVH never picks the one facing away and prefers the near one."""
    near = AreaLight.rectangle([-0.5, 2.0, -0.5], [1, 0, 0], [0, 0, 1], 5.0)  # faces down, toward the receiver
    away = AreaLight.rectangle([1.5, 2.0, -0.5], [0, 0, 1], [1, 0, 0], 5.0)  # faces up
    far = AreaLight.rectangle([-0.5, 20.0, -0.5], [1, 0, 0], [0, 0, 1], 5.0)
    lights = light_arrays([near, away, far])
    bvh = LightSampler("bvh", lights).pmf([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    power = LightSampler("power", lights).pmf([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(power, 1 / 3)
    assert bvh[1] == 0.0 and bvh[0] > 10 * bvh[2] > 0, bvh
    assert bvh.sum() == pytest.approx(1.0, abs=1e-12)


def test_selectors_reject_unknown_modes():
    from lightprobe.errors import ParameterError

    with pytest.raises(ParameterError, match="light sampler must be one of"):
        LightSampler("random", LIGHTS)
