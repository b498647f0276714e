"""The environment's work 8 slots at a time (integrators/stages/environment_lanes.py): the scalar stages' values, no
read or write outside the live slots, and the renderer's choice between the two."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit, prange

from lightprobe.emitters.envmap import EnvironmentMap, env_lookup
from lightprobe.emitters.procedural import constant, sky_with_sun
from lightprobe.integrators.stages.environment_lanes import LANES, applies, radiance_block
from lightprobe.integrators.wavefront import RenderSettings, render

from . import records


@njit(parallel=True)
def _in_lanes(radiance, image, uv, state):
    for block in prange((state.shape[0] + LANES - 1) // LANES):
        radiance_block(radiance, image, uv, state, block * LANES)


@njit
def _one_at_a_time(k, uv, state, radiance):
    for r in range(state.shape[0]):
        if state[r] != 0:
            radiance[r, 0], radiance[r, 1], radiance[r, 2] = env_lookup(k, uv[r, 0], uv[r, 1])


def _map():
    return EnvironmentMap.from_array(sky_with_sun(96, 48, sun_diameter_deg=8.0))


def _slots(n, seed=0):
    rng = np.random.default_rng(seed)
    uv = rng.random((n, 2))
    # the edges of the domain: u = 0 and just below 1 (the wrap), v = 0 and 1 (the clamped rows)
    edges = [[0.0, 0.0], [1.0 - 2**-53, 1.0], [0.999, 0.5], [1e-4, 0.0], [0.5, 1.0], [0.0, 1.0]]
    uv[: min(n, 6)] = edges[: min(n, 6)]
    state = rng.integers(0, 4, n).astype(np.int8)  # SLOT_NONE (0) a quarter of the time
    state[: min(n, 6)] = 1
    return uv, state


@pytest.mark.parametrize("n", [1, 7, 8, 9, 1003])
def test_the_lanes_give_the_scalar_lookup_and_leave_dead_slots_alone(n):
    k = _map().kernel
    uv, state = _slots(n)
    lanes, scalar = np.full((n, 3), -7.0), np.full((n, 3), -7.0)
    _in_lanes(lanes, k.image, uv, state)
    _one_at_a_time(k, uv, state, scalar)
    live = state != 0
    # the same formula; the scalar kernel may fuse a multiply-add, so allow an ulp
    np.testing.assert_allclose(lanes[live], scalar[live], rtol=1e-15, atol=0)
    assert np.all(lanes[~live] == -7.0)


def test_the_lanes_never_write_past_the_arrays():
    k = _map().kernel
    n = 13  # the second block has 3 slots in the arrays and 5 lanes past them
    uv, state = _slots(n + 5)
    state[:] = 1
    radiance = np.full((n + 5, 3), -7.0)
    _in_lanes(radiance[:n], k.image, uv[:n], state[:n])
    assert np.all(radiance[:n] != -7.0)
    assert np.all(radiance[n:] == -7.0)


def test_coordinates_outside_the_domain_give_finite_radiance():
    k = _map().kernel
    uv = np.array([[np.nan, np.nan], [1e300, -1e300], [-5.0, 7.0], [np.inf, -np.inf]])
    state = np.ones(4, np.int8)
    radiance = np.zeros((4, 3))
    _in_lanes(radiance, k.image, uv, state)  # an index from a NaN would read anywhere: must not crash
    assert np.all(np.isfinite(radiance))
    # a NaN is clamped to u = -1/2, v = 0: the texels at u = 1/2 (periodic), not memory before the image
    expected = np.zeros((1, 3))
    _one_at_a_time(k, np.array([[0.5, 0.0]]), np.ones(1, np.int8), expected)
    np.testing.assert_allclose(radiance[0], expected[0], rtol=1e-12)


def test_which_maps_the_lanes_take():
    image = np.zeros((4, 8, 3), np.float32)
    assert applies(image, True)
    assert not applies(image, False)  # nearest lookups
    assert not applies(np.zeros((1, 8, 3), np.float32), True)  # one row: nothing to interpolate between
    assert not applies(image.astype(np.float64), True)
    assert not applies(np.zeros((8, 4, 3), np.float32).transpose(1, 0, 2), True)  # not C-contiguous


def _scene(**env_options):
    from ..test_wavefront import small_scene

    return small_scene((20, 12), **env_options)


def test_a_render_with_the_lanes_equals_one_with_the_scalar_stages(monkeypatch):
    """The whole environment path, with the lanes' sampling and radiance stages or the scalar ones: the same image
    to float32 rounding (bit for bit on the machine measured; a fused multiply-add may differ elsewhere)."""
    from lightprobe.integrators.stages import environment_lanes

    settings = RenderSettings(spp=4, seed=3)
    lanes = render(_scene(), settings)
    assert {"environment_radiance_lanes", "environment_samples_lanes"} <= set(lanes.stats["stages"])
    monkeypatch.setattr(environment_lanes, "applies", lambda image, bilinear: False)
    monkeypatch.setattr(environment_lanes, "samples_apply", lambda k: False)
    scalar = render(_scene(), settings)
    assert {"environment_radiance", "environment_samples"} <= set(scalar.stats["stages"])
    assert not {"environment_radiance_lanes", "environment_samples_lanes"} & set(scalar.stats["stages"])
    np.testing.assert_allclose(lanes.image, scalar.image, rtol=1e-6, atol=0)
    assert np.all(lanes.counts == scalar.counts)


@pytest.mark.parametrize("env", ["nearest", "one row"])
def test_maps_the_lanes_do_not_take_render_through_the_scalar_stage(env, monkeypatch):
    """A white furnace with a map the lanes refuse: a Lambertian sphere under constant radiance L shows rho L, exactly
    with cosine-weighted BSDF samples."""
    from lightprobe.bsdfs import Lambert
    from lightprobe.geometry.camera import Camera
    from lightprobe.geometry.shapes import Sphere
    from lightprobe.scene import Scene

    radiance, albedo = 1.5, 0.6
    if env == "nearest":
        environment = EnvironmentMap.from_array(constant(radiance), lookup="nearest", pdf="exact")
    else:
        environment = EnvironmentMap.from_array(constant(radiance, width=8, height=1))
    scene = Scene(Camera([0, 0, 4], [0, 0, 0], fov=40, resolution=(16, 16)), environment)
    scene.add(Sphere([0, 0, 0], 1.0), Lambert(albedo))
    result = render(scene, RenderSettings(spp=4, strategy="brdf"))
    assert "environment_radiance" in result.stats["stages"]
    np.testing.assert_allclose(result.image[6:10, 6:10], albedo * radiance, rtol=1e-5)
    np.testing.assert_allclose(result.image[0, 0], radiance, rtol=1e-6)


def _sampling_case(m=8, n_bsdf=4, n=3001, seed=4):
    """A pass's worth of environment slots on a map large enough for the small-angle tables: random numbers,
    materials (compensated or not), shading normals, and slots that are dead or BSDF samples."""
    from lightprobe.emitters.envmap_bilinear import SMALL_ANGLE_COLUMNS, SMALL_ANGLE_ROWS

    env = EnvironmentMap.from_array(sky_with_sun(2 * SMALL_ANGLE_COLUMNS, SMALL_ANGLE_ROWS + 8, sun_diameter_deg=6.0))
    rng = np.random.default_rng(seed)
    slots = n * m
    j = np.arange(slots) % m
    state = np.where(j < n_bsdf, 1, np.where(rng.random(slots) < 0.9, 2, 0)).astype(np.int8)
    normals = rng.normal(size=(n, 3))
    frame = np.zeros((n, 9))
    frame[:, 6:] = normals / np.linalg.norm(normals, axis=1)[:, None]
    return {
        "env": env.kernel,
        "compensate": np.array([True, False]),
        "m": m,
        "material": rng.integers(0, 2, n).astype(np.int64),
        "frame": frame,
        "state": state,
        "env_u": rng.random((slots, 2)),
    }


def _sample(stage, case, strategy=None, n_bsdf=None):
    """Run environment-sample stage ``stage`` on the case (``strategy`` and ``n_bsdf`` for the lanes' numbering)."""
    from lightprobe.integrators.techniques import MIS

    nm = case["state"].shape[0]
    m = case["m"]
    n_bsdf = 0 if n_bsdf is None else n_bsdf
    c = records.constants(
        m, n_bsdf=n_bsdf, strategy=MIS if strategy is None else strategy, compensate=case["compensate"]
    )
    cams = records.cameras(nm // m, material=case["material"], frame=case["frame"])
    slots = records.slots(
        nm, state=case["state"].copy(), wdir=np.full((nm, 3), -7.0), tpdf=np.full(nm, -7.0),
        uv=np.full((nm, 2), -7.0), u=case["env_u"],
    )  # fmt: skip
    records.run(stage, records.records(c, cams, slots, env=case["env"]))
    return {"state": slots.state, "wdir": slots.wdir, "tpdf": slots.tpdf, "uv": slots.uv}


@pytest.mark.parametrize(("m", "n_bsdf", "n"), [(8, 4, 3001), (5, 2, 7), (1, 0, 13)])
def test_environment_samples_in_lanes_are_the_scalar_stages(m, n_bsdf, n):
    """Directions, densities and dropped slots the same bits as wavefront._env_sample_stage's; lat-long
    coordinates within an ulp (a fused multiply-add may differ); BSDF slots and dead slots untouched."""
    from lightprobe.integrators.techniques import ENV, MIS

    case = _sampling_case(m, n_bsdf, n)
    scalar = _sample("environment_samples", case)
    strategy = MIS if n_bsdf else ENV
    lanes = _sample("environment_samples_lanes", case, strategy, n_bsdf)
    assert np.array_equal(lanes["state"], scalar["state"])
    assert np.count_nonzero(scalar["state"] == 0) > np.count_nonzero(case["state"] == 0)  # some were dropped
    assert np.array_equal(lanes["wdir"], scalar["wdir"])
    assert np.array_equal(lanes["tpdf"], scalar["tpdf"])
    np.testing.assert_allclose(lanes["uv"], scalar["uv"], rtol=3e-16, atol=1e-300)
    untouched = case["state"] != 2
    assert np.all(lanes["wdir"][untouched] == -7.0) and np.all(lanes["tpdf"][untouched] == -7.0)


def test_strategies_without_environment_samples_give_the_lanes_nothing():
    """Under ``brdf`` no slot is an environment sample: the lanes stage writes nothing (it is given no slots)."""
    from lightprobe.integrators.techniques import BRDF

    case = _sampling_case(m=4, n_bsdf=4, n=64)
    case["state"][:] = 2  # even slots marked as environment samples are not the lanes' under BRDF
    lanes = _sample("environment_samples_lanes", case, BRDF, 4)
    assert np.all(lanes["wdir"] == -7.0) and np.all(lanes["state"] == 2)


def test_guide_tables_bracket_each_buckets_crossing():
    """Entry g of a guide is the largest index whose running sum is at most g / G of the total; -1 for a row
    without weight (the compensated density has many)."""
    from lightprobe.emitters.envmap_bilinear import GUIDE_BUCKETS

    k = _sampling_case(n=1)["env"]
    for sums, guide in ((k.conditional_cdf, k.row_guide), (k.comp_conditional_cdf, k.comp_row_guide)):
        assert guide.shape == (sums.shape[0], GUIDE_BUCKETS + 1) and guide.dtype == np.int32
        for j in range(sums.shape[0]):
            total = sums[j, -1]
            if not total > 0.0:
                assert np.all(guide[j] == -1)
                continue
            thresholds = np.arange(GUIDE_BUCKETS + 1) / GUIDE_BUCKETS * total
            expected = np.searchsorted(sums[j, :-1], thresholds, side="right") - 1
            assert np.array_equal(guide[j], expected)
    assert np.any(np.all(k.comp_row_guide == -1, axis=1))  # rows of weight 0 were covered
    thresholds = np.arange(GUIDE_BUCKETS + 1) / GUIDE_BUCKETS * k.marginal_cdf[-1]
    assert np.array_equal(k.marginal_guide, np.searchsorted(k.marginal_cdf[:-1], thresholds, side="right") - 1)


@pytest.mark.parametrize("corrupt", ["zeros", "last", "shuffled", "swapped"])
def test_a_wrong_guide_changes_no_sample(corrupt):
    """The lanes check each guide bracket with the search's own compares and search [0, top] where it fails, so
    even wrong guides give the scalar stage's samples (only slower)."""
    case = _sampling_case(m=5, n_bsdf=2, n=701, seed=11)
    k = case["env"]
    rng = np.random.default_rng(12)
    guides = {}
    for name in ("marginal_guide", "row_guide", "comp_marginal_guide", "comp_row_guide"):
        g = getattr(k, name)
        if corrupt == "zeros":
            g = np.zeros_like(g)
        elif corrupt == "last":
            g = np.full_like(g, (k.marginal_cdf.shape[0] if "marginal" in name else k.conditional_cdf.shape[1]) - 2)
        elif corrupt == "shuffled":
            g = np.ascontiguousarray(rng.permutation(g.ravel()).reshape(g.shape))
        else:  # the plain density's guides for the compensated one's and back
            other = name.replace("comp_", "") if name.startswith("comp_") else "comp_" + name
            g = getattr(k, other)
        guides[name] = g
    case["env"] = k._replace(**guides)
    scalar = _sample("environment_samples", case)
    from lightprobe.integrators.techniques import MIS

    lanes = _sample("environment_samples_lanes", case, MIS, 2)
    assert np.array_equal(lanes["state"], scalar["state"])
    assert np.array_equal(lanes["wdir"], scalar["wdir"])
    assert np.array_equal(lanes["tpdf"], scalar["tpdf"])


@pytest.mark.parametrize(
    ("strategy_name", "m", "n_bsdf"), [("mis", 8, 4), ("mis", 5, 2), ("brdf", 3, 3), ("env", 4, 0)]
)
def test_coordinates_and_densities_in_lanes_are_the_scalar_stages(strategy_name, m, n_bsdf):
    """The scalar coordinates stage's lat-long coordinates and MIS densities, within the lanes' atan2 and acos's 2
    ulp (the scalar stage calls the C library), for every slot the strategy's numbering gives the lanes that is
    neither dead nor an environment sample; every other slot untouched."""
    from lightprobe.integrators.techniques import STRATEGIES

    strategy = STRATEGIES[strategy_name]
    mis = strategy_name == "mis"
    case = _sampling_case(m=m, n_bsdf=n_bsdf, n=1003, seed=9)
    rng = np.random.default_rng(10)
    slots = case["state"].shape[0]
    j = np.arange(slots) % m
    ours = j < (n_bsdf if strategy_name == "mis" else (0 if strategy_name == "env" else m))
    state = np.where(ours, rng.choice([0, 1, 1, 1, 3], slots), 2).astype(np.int8)  # dead, BSDF, hemisphere
    directions = rng.normal(size=(slots, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    poles = np.flatnonzero(ours)[:3]  # the poles and u = 0 exactly, in slots of the lanes' numbering
    directions[poles] = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])[: poles.size]
    state[poles] = 1

    def coords(stage):
        c = records.constants(m, n_bsdf=n_bsdf, strategy=strategy, compensate=case["compensate"])
        cams = records.cameras(slots // m, material=case["material"])
        out = records.slots(
            slots, state=state, wdir=directions, uv=np.full((slots, 2), -7.0), light_pdf=np.full(slots, -7.0)
        )
        records.run(stage, records.records(c, cams, out, env=case["env"]))
        return out.uv, out.light_pdf

    uv_s, epdf_s = coords("environment_coords")
    uv_l, epdf_l = coords("environment_coords_lanes")
    # u on the circle: 1 - 1e-17 rounds to 1 and wraps to 0
    du = np.abs(uv_l[:, 0] - uv_s[:, 0])
    assert np.minimum(du, 1.0 - du).max() <= 4.5e-16  # 4 ulp of numbers near 1
    assert np.abs(uv_l[:, 1] - uv_s[:, 1]).max() <= 4.5e-16
    np.testing.assert_allclose(epdf_l, epdf_s, rtol=1e-12, atol=0.0)
    if strategy_name != "env":  # (under env no slot is the stage's)
        assert np.count_nonzero(uv_l != -7.0) > 100  # coordinates, not untouched slots, were compared
    assert np.all(uv_l[(state == 0) | (state == 2)] == -7.0)
    assert np.count_nonzero(epdf_l != -7.0) == (np.count_nonzero(state == 1) if mis else 0)
    if mis and strategy_name != "env":
        assert np.count_nonzero(epdf_l > 0) > 100  # densities, not zeros, were compared
