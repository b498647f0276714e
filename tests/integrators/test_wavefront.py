"""The renderer: white furnace, all strategies converge to one image (per-pixel z-test), determinism across
threads and pass sizes, time limits and interruption keep what was accumulated, agreement with Mitsuba."""

from __future__ import annotations

import json

import numba
import numpy as np
import pytest

from lightprobe.analysis.metrics import relmse
from lightprobe.bsdfs import GGXConductor, Lambert, Phong, RoughPlastic
from lightprobe.demo import blob_mesh
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.procedural import constant, sky_with_sun
from lightprobe.errors import ParameterError
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.integrators import wavefront
from lightprobe.integrators.accumulation import Accumulator
from lightprobe.integrators.settings import AUTO_BSDF_SAMPLES, AUTO_ENV_SAMPLES, MANY_LIGHTS_PICKS, RESOLVED_PER_SCENE
from lightprobe.integrators.wavefront import RenderSettings, render, result_from
from lightprobe.peer import find_peers, peer_scene
from lightprobe.scene import Scene

from . import STRATEGY_CASES


@pytest.mark.parametrize(("strategy", "heuristic"), [*STRATEGY_CASES, ("env-resampled", "balance")])
def test_white_furnace(strategy, heuristic):
    """A Lambertian sphere alone under constant radiance L: every pixel on it is rho L, every other pixel L."""
    candidates = 4 if strategy.endswith("-resampled") else 1
    strategy = strategy.removesuffix("-resampled")
    radiance, albedo = 1.5, 0.6
    scene = Scene(
        Camera([0, 0, 4], [0, 0, 0], fov=40, resolution=(24, 24)), EnvironmentMap.from_array(constant(radiance))
    )
    scene.add(Sphere([0, 0, 0], 1.0), Lambert(albedo))
    settings = RenderSettings(spp=64, strategy=strategy, heuristic=heuristic, env_candidates=candidates, adaptive=False)
    result = render(scene, settings)
    img, var, n = result.image, result.variance, result.counts
    assert np.all(n == 64)
    on = np.zeros((24, 24), bool)
    on[6:18, 6:18] = True  # the sphere covers the centre of the frame; pixels there are fully on it
    z = np.abs(img[on] - albedo * radiance) / np.sqrt(np.maximum(var[on], 1e-30))
    assert np.all((z < 5) | (np.abs(img[on] - albedo * radiance) < 1e-6)), z.max()
    corners = img[[0, 0, -1, -1], [0, -1, 0, -1]]
    np.testing.assert_allclose(corners, radiance, rtol=1e-6)
    # the mean over the sphere's pixels: a small bias hides in every pixel's noise, not in the mean of 432 values
    standard_error = np.sqrt(var[on].sum()) / var[on].size
    assert abs(img[on].mean() - albedo * radiance) < 4 * standard_error + 1e-6 * radiance, (
        img[on].mean(),
        standard_error,
    )


@pytest.mark.parametrize("strategy", ["cosine", "env", "mis"])
def test_a_mesh_casts_the_closed_form_shadow(strategy):
    """A triangle-mesh sphere (radius r, centre at height d) over a Lambert ground under a constant sky L: the
    ground point straight below sees the sky except a cap of half-angle asin(r/d), so it reflects
    rho L (1 - (r/d)^2).  Fails if shadow rays miss meshes."""
    import trimesh

    from lightprobe.geometry.mesh import TriangleMesh

    radiance, albedo, r, d = 1.0, 0.5, 1.0, 2.0
    ico = trimesh.creation.icosphere(subdivisions=5)  # 20480 triangles: the inscribed polyhedron is 2e-4 smaller
    ball = TriangleMesh.from_arrays(np.asarray(ico.vertices) * r + [0.0, d, 0.0], np.asarray(ico.faces))
    scene = Scene(
        Camera([0, 1, 6], [0, 0, 0], fov=0.5, resolution=(3, 3)), EnvironmentMap.from_array(constant(radiance))
    )
    scene.add(Rectangle.ground(size=40), Lambert(albedo))
    scene.add(ball, Lambert(0.5))
    result = render(scene, RenderSettings(spp=4096, strategy=strategy, seed=5))
    expected = albedo * radiance * (1 - (r / d) ** 2)
    # one channel: under a grey sky the three are the same estimate, not three independent ones
    mean, standard_error = result.image[..., 0].mean(), np.sqrt(result.variance[..., 0].sum()) / 9
    assert abs(mean - expected) < 4 * standard_error + 2e-4, (mean, standard_error)


def small_scene(resolution=(32, 24), **env_options):
    """A sky with a wide sun (so even uniform sampling converges), a mesh, spheres and the ground."""
    sky = sky_with_sun(256, 128, sun_diameter_deg=12.0, sun_radiance=(40.0, 36.0, 30.0))
    env = EnvironmentMap.from_array(sky, **env_options)
    scene = Scene(Camera([0, 1.6, 4.5], [0, 0.5, 0], fov=40, resolution=resolution), env)
    scene.add(Rectangle.ground(size=30), Lambert(0.5))
    scene.add(blob_mesh(2), RoughPlastic([0.6, 0.2, 0.1], 0.3), transform={"scale": 0.5, "translate": [0, 0.6, 0]})
    scene.add(Sphere([-1.1, 0.4, 0.3], 0.4), GGXConductor(0.2, material="Al"))
    scene.add(Sphere([1.1, 0.4, 0.3], 0.4), Phong(0.3, 0.5, 30))
    return scene


def test_automatic_compensation_is_per_material():
    """mis_compensation=None compensates Lambertian materials only (decisions.md 29): a view of a Lambertian ground
    renders as with compensation everywhere, a view filled by a GGX sphere as without (bit for bit), and each
    differs from the other choice.  (Unbiasedness: the 4096-spp reference below uses the default, and every
    strategy's z-test compares against it.)"""
    sky = EnvironmentMap.from_array(sky_with_sun(256, 128, sun_diameter_deg=12.0, sun_radiance=(40.0, 36.0, 30.0)))
    ground = Scene(Camera([0, 2.0, 0], [0, 0, -0.5], fov=30, resolution=(6, 4)), sky)
    ground.add(Rectangle.ground(size=30), Lambert(0.5))
    sphere = Scene(Camera([0, 0.5, 3], [0, 0.5, 0], fov=10, resolution=(6, 4)), sky)
    sphere.add(Sphere([0, 0.5, 0], 0.5), GGXConductor(0.3, material="Au"))
    images = {
        (name, option): render(scene, RenderSettings(spp=16, seed=3, mis_compensation=option)).image
        for name, scene in (("ground", ground), ("sphere", sphere))
        for option in (None, True, False)
    }
    np.testing.assert_array_equal(images["ground", None], images["ground", True])
    assert not np.array_equal(images["ground", None], images["ground", False])
    np.testing.assert_array_equal(images["sphere", None], images["sphere", False])
    assert not np.array_equal(images["sphere", None], images["sphere", True])


def test_automatic_sample_allocation_and_heuristic():
    """n_bsdf, n_env and heuristic None (decisions.md 33, 34, 93, 97): 8 BSDF + 8 environment samples and the balance
    heuristic where an environment map is the only light; with area lights 1 + 1 and power, 2 BSDF samples where an
    environment map lights the scene beside them; single techniques take as many slots; given values are kept.  The
    stats report what was used, and an automatic render is the explicit one, bit for bit."""
    env_scene = small_scene((6, 4))
    lit = small_scene((6, 4))
    lit.add(Rectangle([-0.5, 3, -0.5], [1, 0, 0], [0, 0, 1]), None, emission=5.0, name="panel")
    dark = Scene(Camera([0, 1, 4], [0, 0.5, 0], resolution=(6, 4)))  # the panel alone: no environment map
    dark.add(Rectangle.ground(size=30), Lambert(0.5))
    dark.add(Rectangle([-0.5, 3, -0.5], [1, 0, 0], [0, 0, 1]), None, emission=5.0, name="panel")

    def used(scene, **options):
        stats = render(scene, RenderSettings(spp=1, **options)).stats
        return stats["n_bsdf"], stats["n_env"], stats["heuristic"]

    # RESOLVED_PER_SCENE names what resolved() fills in (reference checkpoints compare those as resolved)
    filled = RenderSettings().resolved(environment_only=False)
    assert {f for f in RESOLVED_PER_SCENE if getattr(filled, f) is not None} == set(RESOLVED_PER_SCENE)
    assert all(getattr(RenderSettings(), f) is None for f in RESOLVED_PER_SCENE)
    auto_counts = (AUTO_BSDF_SAMPLES, AUTO_ENV_SAMPLES)
    assert auto_counts == (8, 8)
    assert used(env_scene) == (*auto_counts, "balance")
    assert used(lit) == (2, 1, "power")
    assert used(dark) == (1, 1, "power")
    # a single technique takes as many directions as MIS: equal samples are equal rays
    assert used(env_scene, strategy="brdf") == (*auto_counts, "balance")
    assert used(env_scene, n_bsdf=1, n_env=2, heuristic="power") == (1, 2, "power")
    assert used(lit, n_bsdf=2, n_env=3, heuristic="balance") == (2, 3, "balance")
    auto = render(env_scene, RenderSettings(spp=4, seed=5)).image
    explicit = render(env_scene, RenderSettings(spp=4, seed=5, n_bsdf=8, n_env=8, heuristic="balance")).image
    np.testing.assert_array_equal(auto, explicit)
    assert not np.array_equal(auto, render(env_scene, RenderSettings(spp=4, seed=5, n_env=1)).image)
    # the 64-slot limit applies to the counts actually used: 1 + 63 is fine with area lights (K = 1), 8 + 63 is not
    assert used(dark, n_env=63, lights_per_sample=1) == (1, 63, "power")
    # ... and the message says which counts were automatic and what they came to
    automatic = r"\(automatic for this scene: n_bsdf = 1, lights_per_sample = 2\)$"
    with pytest.raises(ParameterError, match=r"lights_per_sample.*" + automatic):
        render(dark, RenderSettings(spp=1, n_env=63))  # automatic K = 2: 1 + 2 x 63 slots
    with pytest.raises(ParameterError, match=r"got 2 and 63 \(automatic for this scene: n_bsdf = 2\)$"):
        render(lit, RenderSettings(spp=1, n_env=63, lights_per_sample=1))  # automatic n_bsdf = 2: 2 + 63 slots
    with pytest.raises(ParameterError, match="got 8 and 63"):
        render(env_scene, RenderSettings(spp=1, n_env=63))


def test_two_lights_are_picked_per_camera_sample_unless_one_light_is_all_there_is():
    """lights_per_sample None (decisions.md 97): K = 2 where anything but an environment map alone lights the
    scene, K = 1 with an environment map alone or a single delta light (a point, a spot, a directional light of
    angle 0: every sample is the same direction); a given K is kept; the automatic render is the explicit one."""
    from lightprobe.emitters.directional import DirectionalLight
    from lightprobe.emitters.punctual import PointLight, SpotLight

    def scene(*lights, environment=False, panel=False):
        s = small_scene((6, 4)) if environment else Scene(Camera([0, 1, 4], [0, 0.5, 0], resolution=(6, 4)))
        if not environment:
            s.add(Rectangle([-3, 0, -3], [0, 0, 6], [6, 0, 0]), Lambert(0.5), name="ground")
        if panel:
            s.add(Rectangle([-0.5, 3, -0.5], [1, 0, 0], [0, 0, 1]), None, emission=5.0, name="panel")
        for light in lights:
            s.add_light(light)
        return s

    def k(s, **options):
        return render(s, RenderSettings(spp=1, **options)).stats["lights_per_sample"]

    point = PointLight([0, 2, 0], 3.0)
    assert k(scene(environment=True)) == 1
    assert k(scene(point)) == 1
    assert k(scene(SpotLight([0, 2, 0], [0, 0, 0], 3.0))) == 1
    assert k(scene(DirectionalLight([0, -1, 0], 2.0))) == 1
    assert k(scene(DirectionalLight([0, -1, 0], 2.0, angle=1.0))) == 2  # a disc: its samples differ
    assert k(scene(point, PointLight([1, 2, 0], 1.0))) == 2
    assert k(scene(point, environment=True)) == 2
    assert k(scene(panel=True)) == 2
    assert k(scene(environment=True, panel=True)) == 2
    assert k(scene(panel=True), lights_per_sample=1) == 1
    # many lights (64 rows of the light BVH or more): 4 picks (decisions.md 118), where the slots hold them
    grid = [PointLight([x - 4.0, 2, z - 4.0], 0.1) for x in range(8) for z in range(8)]
    assert k(scene(*grid[:63])) == 2 and k(scene(*grid)) == MANY_LIGHTS_PICKS == 4
    assert k(scene(*grid), n_env=15) == 4 and k(scene(*grid), n_env=16) == 2  # 1 + 4 x 16 > 64 slots
    assert k(scene(environment=True), lights_per_sample=3) == 3
    lit = scene(panel=True, environment=True)
    auto = render(lit, RenderSettings(spp=4, seed=5)).image
    np.testing.assert_array_equal(auto, render(lit, RenderSettings(spp=4, seed=5, lights_per_sample=2)).image)
    assert not np.array_equal(auto, render(lit, RenderSettings(spp=4, seed=5, lights_per_sample=1)).image)


def test_a_render_builds_its_light_table_once_and_its_plan_holds_it(monkeypatch):
    """resolve() builds the light table and its selector once; the passes read them from the plan (the table was
    built again by the passes, and the delta lights counted from a third copy of the lights' rows)."""
    from lightprobe.emitters.punctual import PointLight

    scene = small_scene((6, 4))
    scene.add(Rectangle([-0.5, 3, -0.5], [1, 0, 0], [0, 0, 1]), None, emission=5.0, name="panel")
    scene.add_light(PointLight([0, 2, 0], 3.0))
    built = []
    table = Scene.light_table
    monkeypatch.setattr(Scene, "light_table", lambda self: built.append(1) or table(self))
    plan = wavefront.resolve(scene, RenderSettings(spp=1, light_sampler="power"))
    assert len(built) == 1 and plan.delta_lights == 1
    assert plan.lights.kind.shape[0] == 3 and plan.selector.n_lights == 3 and plan.selector.cdf.shape[0] == 3
    built.clear()
    result = render(scene, RenderSettings(spp=2, seed=1, light_sampler="power"))
    assert len(built) == 1 and np.isfinite(result.image).all()


@pytest.fixture(scope="module")
def reference():
    return render(small_scene(), RenderSettings(spp=4096, strategy="mis", seed=12345))


@pytest.mark.parametrize(
    ("strategy", "heuristic"),
    [
        *STRATEGY_CASES,
        ("mis-compensated", "power"),
        ("mis-1bsdf-3env", "power"),
        ("mis-3bsdf-1env", "balance"),
        ("env-resampled", "balance"),
        ("mis-resampled", "power"),
        ("mis-compensated-resampled", "balance"),
    ],
)
def test_every_strategy_converges_to_the_reference(reference, strategy, heuristic):
    """Unequal BSDF and environment sample counts check that the MIS weights use them (sample-count-weighted
    densities, Veach's n_i p_i).  Resampled environment samples (RIS, 4 candidates) alone and under MIS."""
    compensated = strategy.startswith("mis-compensated")
    candidates = 4 if strategy.endswith("-resampled") else 1
    counts = {"mis-1bsdf-3env": (1, 3), "mis-3bsdf-1env": (3, 1)}.get(strategy, (1, 1))
    strategy = strategy.removesuffix("-resampled")
    strategy = "mis" if strategy in ("mis-1bsdf-3env", "mis-3bsdf-1env") else strategy
    # Techniques that find the sun only by chance (hemisphere and BSDF sampling) have heavy-tailed estimates: at
    # 1024 spp their sample variance underestimates the true one where the sun was rarely hit (uniform: max |z| 11,
    # brdf: 14, mean z -0.09 and -0.17); at 8192 spp they pass (max |z| 3.1 and 3.2, mean z -0.008 and -0.03).
    spp = 8192 if strategy in ("uniform", "cosine", "brdf") else 1024
    settings = RenderSettings(
        spp=spp,
        strategy="mis" if compensated else strategy,
        heuristic=heuristic,
        mis_compensation=compensated,
        n_bsdf=counts[0],
        n_env=counts[1],
        env_candidates=candidates,
        seed=7,
    )
    result = render(small_scene(), settings)
    z = (result.image - reference.image) / np.sqrt(result.variance + reference.variance + 1e-12)
    # per-pixel z-test over 32 x 24 x 3 values: a handful beyond 4 sigma at most (heavy tails), none beyond 8,
    # and no bias in the mean
    assert np.mean(np.abs(z) > 4) < 0.005, (strategy, np.sort(np.abs(z).ravel())[-5:])
    assert np.abs(z).max() < 8
    assert abs(np.mean(z)) < 0.1


def test_mis_has_lower_error_than_either_technique_alone(reference):
    err = {}
    for strategy in ("brdf", "env", "mis"):
        result = render(small_scene(), RenderSettings(spp=64, strategy=strategy, seed=3))
        err[strategy] = np.mean((result.image - reference.image) ** 2)
    assert err["mis"] < min(err["brdf"], err["env"])


@pytest.mark.parametrize(
    ("sampler", "spp", "adaptive"), [("sobol", 12, False), ("independent", 12, False), ("sobol", 24, True)]
)
def test_bit_identical_across_threads_and_pass_sizes(sampler, spp, adaptive):
    scene = small_scene((20, 12))
    options = {"spp": spp, "sampler": sampler, "adaptive": adaptive}
    base = assert_the_same_bits_on_any_threads_and_pass_size(scene, options)
    if adaptive:  # the counts do differ, so the passes differ in shape; 24 spp: a pilot of 4, then 4 x 2^k
        assert base.counts.min() < base.counts.max()
        assert set(np.unique(base.counts)) <= {4, 8, 16, 32, 64, 128} and base.counts.mean() <= 24
    assert render(scene, RenderSettings(seed=1, **options)).image.tobytes() != base.image.tobytes()


def assert_the_same_bits_on_any_threads_and_pass_size(scene, options: dict):
    """``scene`` rendered with ``options`` on 2 threads, on 1, and in passes of 100 and of 7 camera samples: the
    same counts, image and variance, bit for bit; returns the first render."""
    base = render(scene, RenderSettings(threads=2, **options))
    for settings in (
        RenderSettings(threads=1, **options),
        RenderSettings(pass_samples=100, **options),
        RenderSettings(pass_samples=7, threads=1, **options),
    ):
        other = render(scene, settings)
        np.testing.assert_array_equal(other.counts, base.counts)
        np.testing.assert_array_equal(other.image, base.image)
        np.testing.assert_array_equal(other.variance, base.variance)
    return base


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one core: no thread count to restore")
def test_a_render_gives_its_caller_back_the_thread_count_it_had():
    """A render that names its threads runs on them and leaves the caller's Numba thread count as it found it."""
    before = numba.get_num_threads()
    try:
        for mine, asked in ((1, 2), (2, 1)):
            numba.set_num_threads(mine)
            result = render(small_scene((8, 6)), RenderSettings(spp=1, threads=asked))
            assert result.stats["threads"] == asked and numba.get_num_threads() == mine
    finally:
        numba.set_num_threads(before)


def test_an_adaptive_render_is_unbiased_and_spends_its_samples_where_the_noise_is(reference):
    """Adaptive sampling (integrators/adaptive.py): a 256-spp pilot, then 1024 spp on average.  Counts differ by
    pixel, the mean stays within the budget, and the image passes the same per-pixel z-test against the uniform
    4096-spp reference as every strategy: a pixel's count comes from its neighbours' pilot, not its own."""
    result = render(small_scene(), RenderSettings(spp=1024, seed=7, adaptive=True))
    counts = result.counts
    assert counts.min() == 256 and counts.max() > 1024 and counts.mean() <= 1024
    assert set(np.unique(counts)) <= {256, 512, 1024, 2048, 4096, 8192}
    z = (result.image - reference.image) / np.sqrt(result.variance + reference.variance + 1e-12)
    assert np.mean(np.abs(z) > 4) < 0.005, np.sort(np.abs(z).ravel())[-5:]
    assert np.abs(z).max() < 8
    assert abs(np.mean(z)) < 0.1
    # equal samples on average, lower error than spending them evenly
    uniform = render(small_scene(), RenderSettings(spp=1024, seed=7, adaptive=False))
    adaptive_err, uniform_err = relmse(result.image, reference.image), relmse(uniform.image, reference.image)
    assert adaptive_err < uniform_err, (adaptive_err, uniform_err)


def test_an_adaptive_render_plans_its_counts_within_a_time_limit(monkeypatch):
    """With a time limit an adaptive render's pilot and first mean count come from the time the pilot took (and
    the counts are planned again after every round).  A limit with room to spare gives the image of the same render
    without one, bit for bit; a tight one (here a clock that ticks 10 ms each time it is read, so the plan is the
    same every run) a smaller pilot and mean, still pilot x 2^k per pixel, and the same image twice."""
    scene = small_scene((20, 12))
    free = render(scene, RenderSettings(spp=24, adaptive=True))
    roomy = render(scene, RenderSettings(spp=24, adaptive=True, time_limit=1e6))
    assert not roomy.stats["stopped_by_time_limit"] and roomy.stats["adaptive_pilot_spp"] == 4
    for name in ("counts", "image", "variance"):
        np.testing.assert_array_equal(getattr(roomy, name), getattr(free, name))
    tight = []
    for _ in range(2):
        ticks = iter(range(10**6))
        monkeypatch.setattr(wavefront, "_clock", lambda ticks=ticks: 0.01 * next(ticks))
        tight.append(render(scene, RenderSettings(spp=4096, adaptive=True, time_limit=0.3)))
    stats, counts = tight[0].stats, tight[0].counts
    pilot = stats["adaptive_pilot_spp"]
    assert 1 <= pilot < 1024 and pilot < stats["adaptive_mean_planned"] < 4096
    assert counts.min() >= pilot and counts.max() > counts.min() and counts.mean() <= 4096
    assert set(np.unique(counts)) <= {pilot << k for k in range(16)}
    np.testing.assert_array_equal(tight[1].counts, counts)
    np.testing.assert_array_equal(tight[1].image, tight[0].image)


def test_adaptive_settings_are_checked():
    scene = small_scene((4, 3))
    for settings, match in (
        (RenderSettings(spp=3, adaptive=True), "adaptive sampling needs spp >= 4"),
        (RenderSettings(spp=8, first_sample=8, adaptive=True), "first_sample must be 0"),
        (RenderSettings(spp=8, first_sample=-1), "first_sample must be >= 0"),
        (RenderSettings(spp=8, first_sample=2**56 - 7), r"first_sample \+ spp must be at most 2\^56"),
        (RenderSettings(spp=2**53 + 1, adaptive=True), r"8 x spp \(adaptive\) must be at most 2\^56"),
        (RenderSettings(spp=8, adaptive=1), "adaptive must be true or false"),
    ):
        with pytest.raises(ParameterError, match=match):
            render(scene, settings)
    first = render(scene, RenderSettings(spp=4))
    with pytest.raises(ParameterError, match="cannot be resumed"):
        render(scene, RenderSettings(spp=8, adaptive=True), resume=first.accumulator)
    # the automatic choice near 2^56: a render that would be adaptive is checked as one
    with pytest.raises(ParameterError, match=r"8 x spp \(adaptive\) must be at most 2\^56"):
        render(scene, RenderSettings(spp=2**53 + 1))


def _saved(accumulator, directory):
    path = directory / "accumulator.npz"
    np.savez(path, **accumulator.to_arrays())
    return path


def test_adaptive_counts_are_the_default_from_16_spp_and_uniform_for_sample_ranges(tmp_path):
    """adaptive=None (decisions.md 99): adaptive counts at spp >= 16 from sample 0; uniform below, for a sample range
    (first_sample > 0), for a render that continues another, and wherever adaptive is given as False."""
    auto = RenderSettings()
    assert auto.adaptive is None and auto.spp == 16 and auto.adaptive_counts()
    assert not RenderSettings(spp=15).adaptive_counts()
    assert not RenderSettings(spp=64, first_sample=16).adaptive_counts()
    assert not RenderSettings(spp=64).adaptive_counts(resumed=True)
    assert not RenderSettings(spp=64, adaptive=False).adaptive_counts()
    assert RenderSettings(spp=4, adaptive=True).adaptive_counts()
    assert RenderSettings(spp=64).uniform_unless_adaptive().adaptive is False
    assert RenderSettings(spp=64, adaptive=True).uniform_unless_adaptive().adaptive is True
    scene = small_scene((20, 12))
    default = render(scene, RenderSettings(spp=16, seed=2))
    assert default.stats["adaptive"] and default.stats["adaptive_pilot_spp"] == 4
    assert default.counts.min() < default.counts.max() and default.counts.mean() <= 16
    assert default.stats["spp_mean"] == default.counts.mean()
    explicit = render(scene, RenderSettings(spp=16, seed=2, adaptive=True))
    np.testing.assert_array_equal(explicit.image, default.image)
    low = render(scene, RenderSettings(spp=15, seed=2))
    assert not low.stats["adaptive"] and np.all(low.counts == 15)
    first = render(scene, RenderSettings(spp=16, seed=2, adaptive=False))
    more = render(scene, RenderSettings(spp=16, seed=2, first_sample=16), resume=first.accumulator)
    assert not more.stats["adaptive"] and np.all(more.counts == 32)
    # a render continues only an accumulator whose every pixel holds first_sample samples: not an adaptive render's
    # counts, and not samples it would take again
    # nor can its statistics be merged with a sample range's: they would hold some samples twice
    later = render(scene, RenderSettings(spp=16, seed=2, first_sample=16))
    with pytest.raises(ParameterError, match="cannot merge an adaptive render's statistics"):
        default.accumulator.merged(later.accumulator)
    with pytest.raises(ParameterError, match="cannot merge an adaptive render's statistics"):
        later.accumulator.merged(default.accumulator.copy())
    saved = Accumulator.from_arrays(dict(np.load(_saved(default.accumulator, tmp_path))))  # through a file too
    with pytest.raises(ParameterError, match="cannot merge an adaptive render's statistics"):
        saved.merged(later.accumulator)
    older = {k: v for k, v in later.accumulator.to_arrays().items() if k != "adaptive"}  # written before the flag
    assert not Accumulator.from_arrays(older).adaptive
    assert np.all(first.accumulator.merged(later.accumulator).count == 32)
    uneven = f"4..{default.counts.max()}"
    for accumulator, first_sample, held in ((default.accumulator, 16, uneven), (first.accumulator, 0, "16..16")):
        with pytest.raises(ParameterError, match=f"resume: the accumulator holds {held} samples per pixel"):
            render(scene, RenderSettings(spp=16, first_sample=first_sample), resume=accumulator)


@pytest.mark.parametrize("sampler", ["sobol", "independent"])
def test_split_sample_ranges_resume_bit_for_bit_and_merge_exactly(sampler):
    scene = small_scene((20, 12))
    whole = render(scene, RenderSettings(spp=12, sampler=sampler, pass_samples=500, adaptive=False))
    first = render(scene, RenderSettings(spp=5, sampler=sampler))
    second = render(scene, RenderSettings(spp=7, first_sample=5, sampler=sampler, threads=1))
    # resuming the first range with the second: the same operations in the same order as one render
    resumed = render(scene, RenderSettings(spp=7, first_sample=5, sampler=sampler), resume=first.accumulator)
    np.testing.assert_array_equal(resumed.image, whole.image)
    np.testing.assert_array_equal(resumed.variance, whole.variance)
    np.testing.assert_array_equal(first.accumulator.count, np.full(240, 5))  # resume worked on a copy
    # merging the two ranges (in either order): equal up to float64 rounding
    for merged in (first.accumulator.merged(second.accumulator), second.accumulator.merged(first.accumulator)):
        out = result_from(merged, 20, 12)
        np.testing.assert_allclose(merged.mean, whole.accumulator.mean, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(merged.m2, whole.accumulator.m2, rtol=1e-9, atol=1e-14)
        np.testing.assert_array_equal(out.counts, whole.counts)
        np.testing.assert_allclose(out.variance, whole.variance, rtol=1e-5, atol=1e-12)
    # a range is not the whole: the test can fail
    assert not np.allclose(second.image, whole.image)


@pytest.mark.parametrize("name", ["area", "many"])
def test_scenes_with_lights_render_the_same_bits_on_any_threads_and_pass_size_and_resume_bit_for_bit(name):
    """The reference scenes with area lights under their defaults (decisions 97, 118: 2 or 4 light picks per sample,
    two BSDF samples beside the sky; the outline control variate on, with entries in this image): the same image and
    variance for 1 or 2 threads and any pass size, and a render resumed from a sample range is the whole render, bit
    for bit.  (The determinism tests above use an environment-lit scene, whose one light is picked without a
    selector.)  At 16 spp the defaults take adaptive counts (decisions.md 99): the same bits too; a sample range and a
    resumed render are uniform, so the resume is checked against the uniform render."""
    from lightprobe.reference_scenes import build

    scene = build(name, resolution=(20, 12), lights=200 if name == "many" else None)
    for adaptive in (None, False):
        base = render(scene, RenderSettings(spp=16, threads=2, adaptive=adaptive))
        picks = MANY_LIGHTS_PICKS if name == "many" else 2  # 200 lights; the area scene's 18 (decisions.md 118)
        assert base.stats["lights_per_sample"] == picks and base.stats["outline_pixels"] > 0
        assert base.stats["adaptive"] == (adaptive is None)
        for settings in (
            RenderSettings(spp=16, threads=1, adaptive=adaptive),
            RenderSettings(spp=16, pass_samples=100, adaptive=adaptive),
            RenderSettings(spp=16, pass_samples=7, threads=1, adaptive=adaptive),
        ):
            other = render(scene, settings)
            np.testing.assert_array_equal(other.counts, base.counts)
            np.testing.assert_array_equal(other.image, base.image)
            np.testing.assert_array_equal(other.variance, base.variance)
    first = render(scene, RenderSettings(spp=7))
    resumed = render(scene, RenderSettings(spp=9, first_sample=7, pass_samples=50), resume=first.accumulator)
    np.testing.assert_array_equal(resumed.image, base.image)
    np.testing.assert_array_equal(resumed.variance, base.variance)
    assert render(scene, RenderSettings(spp=16, seed=1, adaptive=False)).image.tobytes() != base.image.tobytes()


def test_sobol_has_lower_error_than_independent_at_equal_samples(reference):
    # the mean over three seeds: the small scene's wide sun on a Phong lobe gives single 16-spp images whose error
    # varies 3x from seed to seed (sobol 4 + 1: 0.00048-0.00116), which one seed would compare
    err = {}
    for sampler in ("sobol", "independent"):
        images = [render(small_scene(), RenderSettings(spp=16, sampler=sampler, seed=seed)).image for seed in (4, 5, 6)]
        err[sampler] = np.mean([np.mean((image - reference.image) ** 2) for image in images])
    assert err["sobol"] < 0.8 * err["independent"], err


def test_time_limit_keeps_the_result():
    scene = small_scene((64, 48))
    result = render(scene, RenderSettings(spp=100_000, time_limit=0.3, pass_samples=4000, adaptive=False))
    stats = result.stats
    assert stats["stopped_by_time_limit"] and 1 <= stats["spp_done"] < 100_000
    assert stats["spp_max"] - stats["spp_done"] <= 1  # an unfinished pass leaves some pixels one pass behind
    assert np.all(np.isfinite(result.image)) and result.image.mean() > 0


def test_a_time_limit_sizes_the_last_round_to_end_at_it(monkeypatch):
    """Under a time limit the uniform rounds take the samples that fit in the time left, at the time per sample of
    the round before, instead of a whole pass that may run far past the limit (here one pass would hold every
    sample).  A clock that advances 1 ms per camera sample makes the timing exact: 0.5 s buys 10 spp of 48
    pixels, and the image is the 10-spp render's, bit for bit."""
    scene = small_scene((8, 6))
    now = [0.0]
    run = wavefront._Pass.run

    def timed_run(self, acc, pixels, spp_now, sample_start):
        now[0] += 1e-3 * pixels.size * spp_now
        return run(self, acc, pixels, spp_now, sample_start)

    monkeypatch.setattr(wavefront._Pass, "run", timed_run)
    monkeypatch.setattr(wavefront, "_clock", lambda: now[0])
    limited = render(scene, RenderSettings(spp=4096, time_limit=0.5, adaptive=False))
    assert limited.stats["stopped_by_time_limit"]
    np.testing.assert_array_equal(limited.counts, 10)
    assert limited.stats["seconds"] == pytest.approx(0.48)
    monkeypatch.setattr(wavefront, "_clock", wavefront.time.perf_counter)
    free = render(scene, RenderSettings(spp=10, adaptive=False))
    for name in ("counts", "image", "variance"):
        np.testing.assert_array_equal(getattr(limited, name), getattr(free, name))


def test_the_default_pass_holds_at_most_2_22_shading_slots():
    """2^19 camera samples per pass, fewer where they would take more than 2^22 slots (decisions.md 40, 51); a
    pass_samples given is taken as it is, past that cap (2^17 x 64 = 2^23 slots, about 2 GB of pass buffers: 2^19
    took about 20 GB, populated when mapped, and ran the test suite's process out of memory on a 24 GB machine)."""
    passes = [wavefront.default_pass_samples(m) for m in (1, 8, 9, 16, 64)]
    assert passes == [1 << 19, 1 << 19, 466033, 1 << 18, 1 << 16]
    scene = small_scene((64, 48))
    auto = render(scene, RenderSettings(spp=4096, strategy="brdf", n_bsdf=64, n_env=0, time_limit=1e-3))
    assert auto.stats["spp_per_pass"] == (1 << 16) // (64 * 48)
    given = render(
        scene, RenderSettings(spp=4096, strategy="brdf", n_bsdf=64, n_env=0, time_limit=1e-3, pass_samples=1 << 17)
    )
    assert given.stats["spp_per_pass"] == (1 << 17) // (64 * 48) > auto.stats["spp_per_pass"]


def test_interruption_keeps_what_was_accumulated():
    scene = small_scene((16, 12))
    calls = []

    def interrupt(stats):
        calls.append(stats["passes"])
        if stats["passes"] == 3:
            raise KeyboardInterrupt

    result = render(scene, RenderSettings(spp=64, pass_samples=16 * 12 * 2), progress=interrupt)
    # rounds of 1, 2, 2 samples per pixel (the first round is always one sample)
    assert result.stats["interrupted"] and result.stats["spp_done"] == 5
    full = render(scene, RenderSettings(spp=5))
    np.testing.assert_array_equal(result.image, full.image)


def test_ctrl_c_stops_at_the_end_of_a_pass_and_never_before_every_pixel_has_a_sample():
    """A real SIGINT during the first pass of the first round (4 bands of 48 pixels) stops the render only once
    every pixel holds one sample; a second SIGINT stops it at once."""
    import os
    import signal

    scene = small_scene((16, 12))
    settings = RenderSettings(spp=64, pass_samples=48)
    handler_before = signal.getsignal(signal.SIGINT)  # SIG_IGN when the suite runs in a background job

    def ctrl_c(times):
        def progress(stats):
            if stats["passes"] == 1:
                for _ in range(times):
                    os.kill(os.getpid(), signal.SIGINT)

        return progress

    once = render(scene, settings, progress=ctrl_c(1))
    assert once.stats["interrupted"] and once.stats["passes"] == 4
    assert once.counts.min() == once.counts.max() == 1 and once.image.mean() > 0
    np.testing.assert_array_equal(once.image, render(scene, RenderSettings(spp=1)).image)
    twice = render(scene, settings, progress=ctrl_c(2))
    assert twice.stats["interrupted"] and twice.stats["passes"] == 1
    assert signal.getsignal(signal.SIGINT) is handler_before  # the render's handler is gone, the caller's is back


def test_outputs_are_finite_and_stats_complete():
    result = render(small_scene((16, 12)), RenderSettings(spp=4))
    for key in ("seconds", "samples_per_s", "rays_per_s", "camera_rays", "shadow_rays", "embree_rays"):
        assert result.stats[key] > 0, key
    assert result.stats["nonfinite_samples"] == 0
    assert np.all(np.isfinite(result.image)) and np.all(np.isfinite(result.variance))


def test_bad_settings():
    scene = small_scene((8, 8))
    for settings, match in [
        (RenderSettings(strategy="magic"), "strategy"),
        (RenderSettings(heuristic="max"), "heuristic"),
        (RenderSettings(spp=0), "spp"),
        (RenderSettings(n_bsdf=0, n_env=0), "sample counts"),
        (RenderSettings(strategy="env", mis_compensation=True), "compensation"),
        (RenderSettings(time_limit=-1.0), "time_limit"),
        (RenderSettings(env_candidates=0), "env_candidates must be from 1 to 64"),
        (RenderSettings(sampler="halton"), "sampler must be one of"),
        (RenderSettings(first_sample=-1), "first_sample"),
    ]:
        with pytest.raises(ParameterError, match=match):
            render(scene, settings)
    scene.add(Sphere([0, 3, 0], 0.1), Phong(0.5, 0.4, 10, estimator="chosen_lobe"))
    with pytest.raises(ParameterError, match="mixture"):
        render(scene, RenderSettings(strategy="mis"))


@pytest.mark.skipif(find_peers() is None, reason="../shared/peers is absent")
def test_peer_scene_matches_mitsubas_reference_means():
    """scene.json records Mitsuba 3's 4096-spp image mean and per-object means; ours agree within 1 %."""
    peers = find_peers()
    expected = json.loads((peers / "scene.json").read_text())["reference_image_check"]
    result = render(peer_scene(resolution=(128, 128)), RenderSettings(spp=64, seed=1))
    np.testing.assert_allclose(result.image.reshape(-1, 3).mean(axis=0), expected["image_mean_rgb"], rtol=0.01)


def test_a_render_reads_one_plan_resolved_once():
    """``resolve`` works out a render's facts once (issue 58): its settings are ``settings_for``'s, checked; its
    stages are ``plan_for``'s for them and are what the render ran; its delta lights are the point, spot and
    angle-0 directional lights (a sun-sized directional light is not one); the compensation is the render's."""
    from lightprobe.emitters.directional import DirectionalLight
    from lightprobe.emitters.punctual import PointLight, SpotLight

    scene = Scene(Camera([0, 1, 4], [0, 0, 0], resolution=(8, 6)), EnvironmentMap.from_array(constant(0.5)))
    scene.add(Rectangle([-4, 0, -4], [0, 0, 8], [8, 0, 0]), Lambert(0.5))
    for light in (
        PointLight([0, 2, 0], 3.0),
        SpotLight([1, 2, 0], [0, 0, 0], 3.0),
        DirectionalLight([0, 1, 0], 1.0),
        DirectionalLight([1, 1, 0], 1.0, angle=0.53),
    ):
        scene.add_light(light)
    settings = RenderSettings(spp=2, adaptive=False)
    plan = wavefront.resolve(scene, settings)
    assert plan.settings == wavefront.settings_for(scene, settings)
    assert plan.pipeline == wavefront.plan_for(scene, plan.settings)
    assert plan.delta_lights == 3 and not plan.pipeline.environment_alone
    result = render(scene, settings)
    assert result.stats["stages"] == list(plan.pipeline.stages())
    assert result.stats["mis_compensation"] == plan.compensated
    # the map alone: no selector, one pick a sample, and the stages that sample the map without one
    alone = Scene(Camera([0, 1, 4], [0, 0, 0], resolution=(8, 6)), EnvironmentMap.from_array(constant(0.5)))
    alone.add(Rectangle([-4, 0, -4], [0, 0, 8], [8, 0, 0]), Lambert(0.5))
    plan = wavefront.resolve(alone, settings)
    assert plan.pipeline.environment_alone and plan.delta_lights == 0
    with pytest.raises(ParameterError, match="env_candidates applies to scenes lit by an environment map alone"):
        wavefront.resolve(scene, RenderSettings(env_candidates=4))


def test_a_finished_render_holds_no_pass_buffers():
    """A render's pass buffers (GBs at the default pass size) are freed when it returns, not at the cyclic
    collector's next run: the stage loop is looked up by its literal group, so no exception's traceback keeps the
    pass's frames in a reference cycle (with the collector off, the old lookup left every render's ``_Pass``)."""
    import gc

    scene = small_scene((8, 6))
    render(scene, RenderSettings(spp=2))
    gc.collect()
    gc.disable()
    try:
        for seed in range(3):
            render(scene, RenderSettings(spp=2, seed=seed))
        alive = [o for o in gc.get_objects() if isinstance(o, wavefront._Pass)]
    finally:
        gc.enable()
    assert alive == []
