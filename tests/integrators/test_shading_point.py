"""Estimators at one shading point: white furnace, zero-variance cases, agreement between all strategies."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.bsdfs import GGXConductor, Lambert, Phong
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.procedural import constant, sky_with_sun
from lightprobe.errors import ParameterError
from lightprobe.integrators.shading_point import estimate

from . import STRATEGY_CASES


@pytest.mark.parametrize(("strategy", "heuristic"), STRATEGY_CASES)
def test_white_furnace(strategy, heuristic):
    """Constant environment L on a Lambertian albedo rho reflects rho L, whatever the strategy."""
    radiance, albedo = 1.5, 0.6  # both exact in float32 (maps are stored as float32)
    env = EnvironmentMap.from_array(constant(radiance))
    est = estimate(env, Lambert(albedo), strategy=strategy, heuristic=heuristic, n=200_000, wo=(0.3, 0.5, 0.8))
    z = np.abs(est.mean - albedo * radiance) / np.maximum(est.std_error, 1e-15)
    assert np.all(z < 5) or np.allclose(est.mean, albedo * radiance, rtol=1e-12), (est.mean, est.std_error)


def test_cosine_and_brdf_sampling_of_lambert_in_a_furnace_have_zero_variance():
    env = EnvironmentMap.from_array(constant(2.0))
    for strategy in ("cosine", "brdf"):
        est = estimate(env, Lambert(0.5), strategy=strategy, n=10_000)
        np.testing.assert_allclose(est.mean, 1.0, rtol=1e-12)
        assert np.all(est.group_variance < 1e-24)


def test_environment_sampling_has_zero_variance_for_the_map_integral():
    """With a texel-exact pdf, L(w)/p(w) is constant: the env estimator of the map's integral is exact."""
    img = sky_with_sun(128, 64, sun_diameter_deg=3.0).mean(axis=2, keepdims=True).repeat(3, axis=2)
    env = EnvironmentMap.from_array(img, lookup="nearest", pdf="exact")
    dirs, pdf = env.sample(np.random.default_rng(0).random((50_000, 2)))
    values = env.eval(dirs)[:, 0] / pdf
    assert np.std(values) / np.mean(values) < 1e-6
    assert np.mean(values) == pytest.approx(env.integral(), rel=1e-6)


MATERIALS = {
    "lambert": Lambert([0.8, 0.5, 0.2]),
    "phong": Phong(0.3, 0.6, 40),
    "ggx": GGXConductor(0.2, material="Au"),
}


@pytest.mark.parametrize("material", list(MATERIALS))
def test_every_strategy_converges_to_the_same_value(material):
    """z-test of each estimator against a high-sample MIS reference, on a sky with a (wide) sun."""
    env = EnvironmentMap.from_array(sky_with_sun(256, 128, sun_diameter_deg=4.0, sun_radiance=(80.0, 70.0, 60.0)))
    bsdf = MATERIALS[material]
    wo = (0.4, 0.6, 0.69)
    ref = estimate(env, bsdf, strategy="mis", heuristic="power", n=2_000_000, wo=wo, seed=99)
    for strategy, heuristic in STRATEGY_CASES:
        for compensated in (False, True) if strategy == "mis" else (False,):
            est = estimate(
                env,
                bsdf,
                strategy=strategy,
                heuristic=heuristic,
                n=400_000,
                wo=wo,
                seed=3,
                compensated=compensated,
            )
            z = np.abs(est.mean - ref.mean) / np.sqrt(est.variance + ref.variance)
            assert np.all(z < 5), (strategy, heuristic, compensated, est.mean, ref.mean, z)


def test_mis_with_more_env_samples_and_visibility():
    env = EnvironmentMap.from_array(sky_with_sun(128, 64, sun_diameter_deg=6.0, sun_radiance=(30.0,) * 3))
    bsdf = Phong(0.5, 0.4, 20)

    def half_blocked(dirs):
        return dirs[:, 0] < 0.2  # a wall on the +X side

    ref = estimate(env, bsdf, strategy="cosine", n=4_000_000, visibility=half_blocked, seed=5)
    est = estimate(env, bsdf, strategy="mis", n_bsdf=1, n_env=3, n=300_000, visibility=half_blocked)
    unblocked = estimate(env, bsdf, strategy="mis", n_bsdf=1, n_env=3, n=300_000)
    z = np.abs(est.mean - ref.mean) / np.sqrt(est.variance + ref.variance)
    assert np.all(z < 5)
    assert np.all(unblocked.mean > est.mean)
    assert est.samples_per_group == 4 and est.n_samples == 1_200_000


def test_deterministic():
    env = EnvironmentMap.from_array(sky_with_sun(64, 32))
    a = estimate(env, Phong(0.2, 0.7, 100), strategy="mis", n=1000, seed=11)
    b = estimate(env, Phong(0.2, 0.7, 100), strategy="mis", n=1000, seed=11)
    np.testing.assert_array_equal(a.mean, b.mean)


def test_refusals():
    env = EnvironmentMap.from_array(constant(1.0))
    with pytest.raises(ParameterError, match="mixture"):
        estimate(env, Phong(0.5, 0.5, 10, estimator="chosen_lobe"), strategy="mis")
    with pytest.raises(ParameterError, match="compensated"):
        estimate(env, Lambert(0.5), strategy="env", compensated=True)
    with pytest.raises(ParameterError, match="strategy"):
        estimate(env, Lambert(0.5), strategy="magic")
    with pytest.raises(ParameterError, match="n_bsdf"):
        estimate(env, Lambert(0.5), strategy="mis", n_bsdf=0, n_env=0)
    with pytest.raises(ParameterError, match="normal"):
        estimate(env, Lambert(0.5), normal=(0, 0, 0))
