"""Light selectors: every pmf sums to one, matches the frequencies of its picks, and select() reports pmf()."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from lightprobe.demo import light_panels
from lightprobe.emitters.area import AreaLight
from lightprobe.emitters.lights import light_arrays
from lightprobe.emitters.punctual import PointLight, SpotLight
from lightprobe.emitters.selection import SELECTORS, LightSampler


def _lights(n_panels: int = 300):
    """Triangles of powers over four decades, two spheres, two rectangles (one two-sided), a point and a spot."""
    from lightprobe.emitters.table import _triangle_lights
    from lightprobe.geometry.mesh import TriangleMesh

    v, f, radiance = light_panels(n_panels, seed=3)
    mesh = TriangleMesh.from_arrays(v, f, smooth=False)
    tris = _triangle_lights(mesh, radiance, False)
    others = light_arrays(
        [
            AreaLight.sphere([2.0, 1.0, 0.0], 0.3, 20.0),
            AreaLight.sphere([-2.0, 0.5, 1.0], 0.1, 500.0),
            AreaLight.rectangle([-1, 3, -1], [2, 0, 0], [0, 0, 2], 5.0),
            AreaLight.rectangle([1, 1, 2], [0, 1, 0], [1, 0, 0], 8.0, two_sided=True),
            PointLight([0.5, 2.0, 0.5], 30.0),
            SpotLight([-1.0, 2.5, 0.0], [0.0, 0.0, 0.0], [50.0, 40.0, 30.0], cone_angle=40.0),
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


def assert_picks_follow_the_pmf(sampler, p, nrm, seed: int, tests: int, compensated: bool = False) -> None:
    """At one receiver: the pmf sums to one, select() reports pmf() for what it picks, and 400,000 picks' counts
    pass a chi-square test against the pmf at 0.01 / ``tests``; no pick where the pmf is 0."""
    n = sampler.arrays.n_lights
    pmf = sampler.pmf(p, nrm, compensated=compensated)
    assert pmf.shape == (n,) and np.all(pmf >= 0)
    assert pmf.sum() == pytest.approx(1.0, abs=1e-12), pmf.sum()
    samples = 400_000
    u = np.random.default_rng(seed).random(samples)
    light, reported = sampler.select(p, nrm, u, compensated=compensated)
    assert np.all(light >= 0)
    np.testing.assert_allclose(reported, pmf[light], rtol=1e-12)
    counts = np.bincount(light, minlength=n)
    # chi-square of the pick counts against the pmf, cells with fewer than 20 expected pooled (with 5, forty
    # cells of a few picks each gave p < 0.01 for 3 % of 200 seeds: the statistic's tail is heavier there)
    expected = samples * pmf
    big = expected >= 20
    observed = np.append(counts[big], counts[~big].sum())
    wanted = np.append(expected[big], expected[~big].sum())
    keep = wanted > 0
    _, p_value = stats.chisquare(observed[keep], wanted[keep] * observed[keep].sum() / wanted[keep].sum())
    assert p_value > 0.01 / tests, p_value
    assert counts[pmf == 0].sum() == 0


@pytest.mark.parametrize(
    "env, compensated", [(None, False), ((40.0, 0.0, 20.0, 5.0), False), ((40.0, 0.0, 20.0, 5.0), True)]
)
@pytest.mark.parametrize("mode", list(SELECTORS))
def test_pmf_sums_to_one_and_matches_the_picks(mode, env, compensated):
    # compensated receivers weigh the environment by the second terms (emitters/selection.py)
    sampler = LightSampler(mode, LIGHTS, env_irradiance=env, env_irradiance_compensated=(8.0, 0.0, 6.0, 1.0))
    assert sampler.arrays.n_lights == LIGHTS.kind.shape[0] + (env is not None)
    for i, (p, nrm) in enumerate(RECEIVERS):
        assert_picks_follow_the_pmf(sampler, p, nrm, 100 + i, 3 * 3 * len(RECEIVERS), compensated)


@pytest.mark.parametrize("mode", list(SELECTORS))
def test_pmf_of_a_light_per_receiver_is_pmfs_entry(mode):
    """``pmf_of`` (one light per receiver, the laboratory's selectors' MIS weights) against ``pmf`` (every light of
    one receiver), and ``select``'s probability: the same numbers."""
    sampler = LightSampler(mode, LIGHTS, env_irradiance=(40.0, 0.0, 20.0, 5.0))
    points = np.array([p for p, _ in RECEIVERS] * 3, dtype=np.float64)
    normals = np.array([n for _, n in RECEIVERS] * 3, dtype=np.float64)
    lights = np.random.default_rng(5).integers(0, sampler.arrays.n_lights, points.shape[0])
    each = np.array([sampler.pmf(p, n)[light] for p, n, light in zip(points, normals, lights, strict=True)])
    np.testing.assert_array_equal(sampler.pmf_of(points, normals, lights), each)
    picked, pmf = sampler.select(points, normals, np.linspace(0.01, 0.99, points.shape[0]))
    np.testing.assert_array_equal(sampler.pmf_of(points, normals, picked), pmf)


def test_power_selection_is_proportional_to_power_and_uniform_is_uniform():
    from lightprobe.emitters.selection import power_of_lights

    power = power_of_lights(LIGHTS)
    p = LightSampler("power", LIGHTS).pmf([0, 0, 0], [0, 1, 0])
    np.testing.assert_allclose(p, power / power.sum(), rtol=1e-9)  # differences of a CDF
    u = LightSampler("uniform", LIGHTS, env_irradiance=(1.0, 0, 0, 0)).pmf([0, 0, 0], [0, 1, 0])
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


@pytest.mark.parametrize("mode", ["power", "bvh"])
def test_the_environment_is_chosen_per_shading_point(mode):
    """A dim sky and one light 1 m over the origin: under the light the light takes most picks, 30 m away the sky
    does (a share by total power gave the sky one value everywhere, 89 % of the picks in a scene with a 16 m
    ground, issue 32); a black sky gets none, and with no area light the sky takes every pick."""
    light = light_arrays([AreaLight.rectangle([-0.25, 1.0, -0.25], [0.5, 0, 0], [0, 0, 0.5], 80.0)])
    sky = (np.pi * 0.2, 0.0, 0.0, 0.0)
    sampler = LightSampler(mode, light, env_irradiance=sky)
    under = sampler.pmf([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    far = sampler.pmf([30.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert under[1] < 0.1 and far[1] > 0.9, (under, far)
    assert sampler.pmf([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]).sum() == pytest.approx(1.0, abs=1e-12)
    black = LightSampler(mode, light, env_irradiance=(0.0, 0.0, 0.0, 0.0)).pmf([30.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(black, [1.0, 0.0])
    none = light_arrays([])
    alone = LightSampler(mode, none, env_irradiance=sky)
    np.testing.assert_allclose(alone.pmf([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]), [1.0])


@pytest.mark.parametrize("mode", ["power", "bvh"])
def test_a_compensated_receiver_weighs_the_environment_by_its_compensated_irradiance(mode):
    """A receiver whose material samples the compensated environment weighs it by the compensated terms: a
    constant sky (compensated terms 0) gets no pick there and every pick elsewhere is the light's; a receiver
    that does not keeps the plain terms; the sky's share follows the terms given (pi max(a + b . n, a / 4))."""
    light = light_arrays([AreaLight.rectangle([-0.25, 1.0, -0.25], [0.5, 0, 0], [0, 0, 0.5], 80.0)])
    sky = (np.pi * 0.2, 0.0, 0.0, 0.0)
    constant = LightSampler(mode, light, env_irradiance=sky, env_irradiance_compensated=(0.0, 0.0, 0.0, 0.0))
    far = ([30.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(constant.pmf(*far, compensated=True), [1.0, 0.0])
    assert constant.pmf(*far)[1] > 0.9
    light_ids, _ = constant.select(*far, np.linspace(0.0, 1.0, 1001, endpoint=False), compensated=True)
    assert np.all(light_ids == 0)
    # nor where the light cannot reach the receiver either (above it, behind its emitting side): the light is
    # picked as the descent does where every bound is zero, and the sky still never
    behind = ([0.0, 2.0, 0.0], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(constant.pmf(*behind, compensated=True), [1.0, 0.0])
    # half the plain terms: the sky's importance halves, I / (I + I_area) as infinite_probability weighs it
    half = LightSampler(mode, light, env_irradiance=sky, env_irradiance_compensated=np.array(sky) / 2)
    plain, compensated = half.pmf(*far)[1], half.pmf(*far, compensated=True)[1]
    area = plain / (1.0 - plain)  # I_env / I_area, plain
    assert compensated == pytest.approx((area / 2) / (1.0 + area / 2), rel=1e-12)
    # not given: the plain terms for every receiver
    same = LightSampler(mode, light, env_irradiance=sky)
    np.testing.assert_array_equal(same.pmf(*far, compensated=True), same.pmf(*far))


def test_the_environments_compensated_irradiance():
    """max(L - mean, 0): nothing for a constant map; a sky lit above only (mean 1/2 of its radiance) keeps half
    its radiance above, so half the plain terms."""
    from lightprobe.emitters.envmap import EnvironmentMap

    constant = EnvironmentMap.from_array(np.full((32, 64, 3), 2.0, np.float32))
    np.testing.assert_array_equal(constant.compensated_irradiance_terms, 0.0)
    upper = np.zeros((256, 512, 3), np.float32)
    upper[:128] = 1.0
    env = EnvironmentMap.from_array(upper)
    assert env.mean_luminance == pytest.approx(0.5, rel=1e-6)
    np.testing.assert_allclose(env.compensated_irradiance_terms, env.irradiance_terms / 2, rtol=1e-6, atol=1e-12)


def test_the_environments_first_order_irradiance():
    """E(n) = a + b . n: pi L for a uniform sky of radiance L in every direction; a sky lit above only gives pi L
    to an upward surface and 0 to a downward one, whatever way a rotation turns it."""
    from lightprobe.emitters.envmap import EnvironmentMap

    uniform = EnvironmentMap.from_array(np.full((32, 64, 3), 2.0, np.float32)).irradiance_terms
    np.testing.assert_allclose(uniform, [2.0 * np.pi, 0.0, 0.0, 0.0], atol=1e-9)
    upper = np.zeros((256, 512, 3), np.float32)
    upper[:128] = 1.0
    terms = EnvironmentMap.from_array(upper).irradiance_terms
    assert terms[0] + terms[2] == pytest.approx(np.pi, rel=1e-3) and abs(terms[0] - terms[2]) < 1e-3
    flipped = EnvironmentMap.from_array(upper, rotation=[[1, 0, 0], [0, -1, 0], [0, 0, -1]]).irradiance_terms
    assert flipped[0] - flipped[2] == pytest.approx(np.pi, rel=1e-3)


@pytest.mark.parametrize("env", [None, (40.0, 0.0, 20.0, 5.0)])
@pytest.mark.parametrize("mode", list(SELECTORS))
def test_the_rescaled_number_is_uniform_within_each_light(mode, env):
    # the renderer picks with the first number of the light sample's pair and samples the light with what is left
    # of it: for a stratified set of u, each light's rescaled numbers must again be a stratified set of [0, 1)
    sampler = LightSampler(mode, LIGHTS, env_irradiance=env)
    n = 1 << 16
    u = (np.arange(n) + 0.5) / n
    for p, nrm in RECEIVERS[:2]:
        light, pmf, rest = sampler.select(p, nrm, u, rescaled=True)
        light2, pmf2 = sampler.select(p, nrm, u)
        assert np.array_equal(light, light2) and np.array_equal(pmf, pmf2)
        assert np.all((rest >= 0.0) & (rest < 1.0))
        for l in np.unique(light):
            r = np.sort(rest[light == l])
            k = r.size
            # k points of an interval of n evenly spaced ones: spaced 1/k apart, to within one point at each end
            if k >= 8:
                assert np.abs(r - (np.arange(k) + 0.5) / k).max() < 1.5 / k, (mode, l, k)
        # and the numbers are u itself, shifted and stretched: in order within each light
        for l in np.unique(light)[:5]:
            assert np.all(np.diff(rest[light == l]) > 0)


def test_a_sphere_counts_by_the_disc_it_shows():
    # A sphere of radius r and a square of area pi r^2 facing the receiver, equally bright and equally far, give it
    # the same irradiance: the BVH should pick them about equally.  With the sphere's whole power 4 pi r^2 L as its
    # bound (pbrt-v4's) the sphere took 0.8 of the picks.
    r, d, side = 0.1, 3.0, np.sqrt(np.pi) * 0.1
    lights = light_arrays(
        [
            AreaLight.sphere([-1.0, d, 0.0], r, 10.0),
            AreaLight.rectangle([1.0 - side / 2, d, -side / 2], [side, 0, 0], [0, 0, side], 10.0),
        ]
    )
    assert lights.geom[1, 9:12] @ [0.0, -1.0, 0.0] == pytest.approx(1.0)  # the square faces down
    pmf = LightSampler("bvh", lights).pmf([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert pmf[0] == pytest.approx(0.5, abs=0.05), pmf


def test_a_light_facing_away_lends_no_light_its_power():
    """issue 33: a bright rectangle facing up beside a ring of 16 small triangles facing down (the area-light
    reference scene).  Median splits paired the rectangle with one triangle: their node's cone took every direction
    and its bound the rectangle's power, and at a ground point, where the rectangle gives nothing, that triangle
    got 0.36 of the picks and its 15 twins 0.01-0.02 each.  The light BVH's splits (pbrt-v4's surface area
    orientation heuristic) keep lights that face apart in separate subtrees: the ring's picks follow what each
    triangle gives the point (pick probability over irradiance within 1.16x across the ring with the eight-wide
    tree, 1.54x with the binary one it collapses; 2.5x between the triangles' irradiances), and the rectangle gets
    none."""
    from lightprobe.reference_scenes import build

    scene = build("area", resolution=(8, 6))
    table = scene.light_table()
    sampler = LightSampler("bvh", table, env_irradiance=scene.environment.irradiance_terms)
    point, normal = [0.3, 0.0, 0.8], [0.0, 1.0, 0.0]
    pmf = sampler.pmf(point, normal)
    ring = np.nonzero(table.kind == 2)[0]  # the triangles
    (rectangle,) = np.nonzero(table.kind == 0)[0]
    assert ring.size == 16 and pmf[rectangle] == 0.0
    g = table.geom[ring]  # each triangle's irradiance at the point, to first order (small, far triangles)
    corners = g[:, 0:3], g[:, 3:6], g[:, 6:9]
    normals = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    areas = 0.5 * np.linalg.norm(normals, axis=1)
    toward = sum(corners) / 3 - np.asarray(point)
    distance = np.linalg.norm(toward, axis=1)
    toward /= distance[:, None]
    cosines = np.abs((toward * normals).sum(axis=1)) / (2 * areas) * np.maximum(0.0, toward @ normal)
    irradiance = areas * cosines / distance**2 * table.radiance[ring].mean(axis=1)
    ratio = pmf[ring] / irradiance
    assert ratio.max() < 1.5 * ratio.min(), ratio
    assert pmf.sum() == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("layout", ["one point", "a line", "point lights"])
def test_the_bvh_builds_where_no_split_separates_the_lights(layout):
    """Thousands of lights at one place (no bucket split exists: median splits take over), along a line, or point
    lights (boxes of no area: every split costs 0) keep the tree within its bit trails' depth, and the pmf still
    sums to one."""
    n = 5000
    x = np.zeros(n) if layout == "one point" else np.linspace(0, 50, n)
    if layout == "point lights":
        lights = light_arrays([PointLight([xi, 2.0, (i % 5) * 0.5], 1.0 + i % 7) for i, xi in enumerate(x)])
    else:
        lights = light_arrays([AreaLight.sphere([xi, 2.0, 0.0], 0.01, 1.0 + i % 7) for i, xi in enumerate(x)])
    sampler = LightSampler("bvh", lights)
    depth = _wide_depths(sampler.arrays.wide_child)
    # balanced enough (no lopsided splits): the binary tree within 4 levels of log2 n, three of its levels a level
    assert depth.max() <= np.ceil((np.ceil(np.log2(n)) + 4) / 3), depth.max()
    pmf = sampler.pmf([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert pmf.sum() == pytest.approx(1.0, abs=1e-9) and np.all(pmf >= 0)
    picked, p = sampler.select([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], np.linspace(0, 1, 64, endpoint=False))
    np.testing.assert_allclose(p, pmf[picked], rtol=1e-12)


def _wide_depths(children):
    """Each node's depth in the eight-wide tree (children have larger indices than their parent)."""
    depth = np.zeros(children.shape[0], np.int64)
    for i in range(children.shape[0]):
        inner = children[i][children[i] >= 0]
        assert np.all(inner > i)
        depth[inner] = depth[i] + 1
    return depth


@pytest.mark.parametrize("count", [1, 2, 9, 300])
def test_the_eight_wide_tree_holds_every_emitting_light_once_and_its_trail_leads_there(count):
    """The collapse of the binary tree: every light with power is one leaf, reached by its trail (the pmf's path);
    every node but a one-light root has 2-8 children, and all of a node's children come before its empty slots."""
    lights = (
        LIGHTS if count == 300 else light_arrays([AreaLight.sphere([i, 2.0, 0.0], 0.1, 1.0 + i) for i in range(count)])
    )
    arrays = LightSampler("bvh", lights).arrays
    children, trail = arrays.wide_child, arrays.light_trail
    leaves = -2 - children[children <= -2]
    assert np.array_equal(np.sort(leaves), np.arange(lights.kind.shape[0])), "each light one leaf"
    per_node = (children != -1).sum(axis=1)
    assert per_node.max() <= 8 and (per_node.min() >= 2 or children.shape[0] == 1)
    for row, k in zip(children, per_node, strict=True):
        assert np.all(row[:k] != -1) and np.all(row[k:] == -1)
    for light in range(lights.kind.shape[0]):
        node, path = 0, int(trail[light])
        while True:
            child = children[node, path & 7]
            path >>= 3
            if child < 0:
                break
            node = child
        assert child == -2 - light
    assert _wide_depths(children).max() <= max(1, int(np.ceil(np.log2(max(count, 2)) / 3)) + 2)


def test_the_orientation_measure_is_pbrts():
    """pbrt-v4's M_omega: pi for a single direction emitting over its hemisphere, 4 pi for a cone of every normal
    (the cost of pairing lights that face apart)."""
    from lightprobe.emitters.selection import _orientation_measure

    assert _orientation_measure(1.0, 0.0) == pytest.approx(np.pi)
    assert _orientation_measure(-1.0, 0.0) == pytest.approx(4 * np.pi)
    assert _orientation_measure(0.0, 0.0) > _orientation_measure(1.0, 0.0)
