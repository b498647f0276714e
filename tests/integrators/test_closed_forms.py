"""Closed forms that the renderer's every path must meet (issue 36).

* Shadows that Embree must decide: an open triangulated annulus (no inner ball, geometry/proxies.py) between a
  ground point and the sky or a rectangle light.  The point's irradiance is Lambert's polygon formula for the
  light (or pi L for the sky) less the annulus' outer polygon plus its inner one; every shadow ray that could meet
  the annulus goes to Embree, through the environment path's 8-ray packets and its single-ray stage and through the
  area-light path's stage.
* White furnaces on the area-light path with an environment: a constant sky of radiance L and two-sided rectangle,
  sphere and triangle lights of the same radiance around a Lambert sphere, which then sees L in every direction and
  reflects rho L, whichever strategy, heuristic, light selector or environment density (plain or MIS-compensated)
  renders it.  (Before, a 5 % error in the environment density there passed every furnace.)
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.procedural import constant
from lightprobe.errors import LightprobeWarning
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.mesh import TriangleMesh
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.integrators import wavefront
from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.scene import Scene

from ..emitters.test_area import polygon_irradiance

SEGMENTS = 24
INNER, OUTER, HEIGHT = 0.15, 0.3, 0.5  # the annulus' radii and height over the point
LIGHT_HEIGHT, LIGHT_HALF = 1.5, 1.0  # a 2 x 2 light facing down; the annulus' shadow on its plane: radius 0.9


def _ring(radius, height):
    """The annulus' polygon of ``SEGMENTS`` vertices at this radius, counter-clockwise seen from above."""
    angle = 2 * np.pi * np.arange(SEGMENTS) / SEGMENTS
    return np.column_stack([radius * np.cos(angle), np.full(SEGMENTS, height), -radius * np.sin(angle)])


def _annulus():
    """The open annulus as 2 x SEGMENTS triangles between its two polygons."""
    vertices = np.concatenate([_ring(INNER, HEIGHT), _ring(OUTER, HEIGHT)])
    faces = []
    for i in range(SEGMENTS):
        j = (i + 1) % SEGMENTS
        faces += [[i, SEGMENTS + i, SEGMENTS + j], [i, SEGMENTS + j, j]]
    return TriangleMesh.from_arrays(vertices, faces, smooth=False)


def _shadow_scene(lit_by):
    """A Lambert ground point at the origin under the annulus, lit by a constant sky or a 2 x 2 light; the camera
    sees the point alone (a 0.05-degree field)."""
    sky = EnvironmentMap.from_array(constant(1.5)) if lit_by == "sky" else None
    scene = Scene(Camera([0.1, 1.2, 0.1], [0.0, 0.0, 0.0], fov=0.05, resolution=(1, 1)), sky)  # through the hole
    scene.add(Rectangle.ground(size=40), Lambert(0.6))
    scene.add(_annulus(), Lambert(0.3), two_sided=True)
    if lit_by == "light":
        corner = [-LIGHT_HALF, LIGHT_HEIGHT, -LIGHT_HALF]
        scene.add(Rectangle(corner, [2 * LIGHT_HALF, 0, 0], [0, 0, 2 * LIGHT_HALF]), emission=2.0, name="light")
    return scene


def _expected(lit_by):
    """rho / pi x the point's irradiance: the sky's pi L or the light's Lambert integral, less what the annulus
    hides (its outer polygon seen from the point, less its inner one; on the light's plane the annulus' shadow,
    radius 0.9, lies inside the light, so what it hides there is the same solid angle)."""
    p, n = np.zeros(3), np.array([0.0, 1.0, 0.0])
    hidden = polygon_irradiance(p, n, list(_ring(OUTER, HEIGHT)), 1.0) - polygon_irradiance(
        p, n, list(_ring(INNER, HEIGHT)), 1.0
    )
    if lit_by == "sky":
        return 0.6 / math.pi * 1.5 * (math.pi - hidden)
    h, s = LIGHT_HEIGHT, LIGHT_HALF
    light = polygon_irradiance(p, n, [[-s, h, -s], [s, h, -s], [s, h, s], [-s, h, s]], 1.0)
    return 0.6 / math.pi * 2.0 * (light - hidden)


@pytest.mark.parametrize(("lit_by", "stage"), [("sky", "packets"), ("sky", "single rays"), ("light", "single rays")])
@pytest.mark.parametrize("strategy", ["env", "mis"])
def test_an_open_mesh_casts_the_closed_form_shadow(monkeypatch, lit_by, stage, strategy):
    """Within 4 standard errors + 2e-4 of the closed form; most shadow rays that could meet the annulus reach
    Embree (the proxies decide none: the annulus is open and the outer sphere holds every ray toward it)."""
    if stage == "single rays":
        plan_for = wavefront.plan_for
        monkeypatch.setattr(
            wavefront, "plan_for", lambda scene, settings: dataclasses.replace(plan_for(scene, settings), packets=False)
        )
    result = render(_shadow_scene(lit_by), RenderSettings(spp=65536, strategy=strategy, seed=2))
    expected = _expected(lit_by)
    mean, se = result.image[0, 0, 0], math.sqrt(result.variance[0, 0, 0])
    assert abs(mean - expected) < 4 * se + 2e-4 * expected, (mean, expected, se, (mean / expected - 1) * 100)
    assert se < 4e-3 * expected  # resolves the annulus' share (20 % of the light, 13 % of the sky) many times over
    assert result.stats["embree_rays"] > 0.1 * result.stats["shadow_rays"], result.stats


def _furnace_scene(radiance):
    """A Lambert sphere (albedo 0.7) under a constant sky of radiance L, with two-sided lights of radiance L: a
    rectangle, a sphere and two triangles around it, so that every direction from the sphere sees L."""
    scene = Scene(
        Camera([0, 0, 4], [0, 0, 0], fov=40, resolution=(16, 16)), EnvironmentMap.from_array(constant(radiance))
    )
    scene.add(Sphere([0, 0, 0], 1.0), Lambert(0.7))
    scene.add(Rectangle([-1.5, -1.5, -2.0], [3.0, 0, 0], [0, 3.0, 0]), emission=radiance, two_sided=True)
    scene.add(Sphere([1.8, 0.8, -0.5], 0.4), emission=radiance)
    triangles = np.array(
        [[-2.0, -0.5, 0.5], [-2.0, 0.5, 0.5], [-2.0, 0.0, -0.5], [0, 2.0, 0], [1, 2.0, 0], [0, 2.0, 1]]
    )
    scene.add(
        TriangleMesh.from_arrays(triangles, [[0, 1, 2], [3, 4, 5]], smooth=False), emission=radiance, two_sided=True
    )
    return scene


FURNACE_CASES = [
    {"strategy": "mis"},
    {"strategy": "mis", "heuristic": "balance", "n_bsdf": 2, "n_env": 2},
    {"strategy": "mis", "mis_compensation": True},
    {"strategy": "mis", "light_sampler": "bvh", "lights_per_sample": 2},
    {"strategy": "mis", "light_sampler": "uniform", "light_strategy": "area"},
    {"strategy": "env"},
    {"strategy": "env", "light_sampler": "bvh"},
    {"strategy": "brdf"},
]


@pytest.mark.parametrize("options", FURNACE_CASES, ids=lambda o: "-".join(f"{v}" for v in o.values()))
def test_white_furnace_with_the_environment_among_area_lights(options):
    """rho L on every pixel fully on the sphere (per pixel within 5 sigma, and their mean within 4 standard
    errors): the environment's samples and densities on the area-light path are as right as the lights'."""
    radiance, albedo = 1.5, 0.7
    # uniform counts: adaptive ones leave the sphere's quiet pixels at the 512-spp pilot, where this furnace's rare
    # large samples make a per-pixel z of 5 common (4.9 % of pixels over 40 seeds, the pooled mean unbiased to 1.5e-5;
    # decisions.md 99)
    result = render(_furnace_scene(radiance), RenderSettings(spp=2048, seed=3, adaptive=False, **options))
    img, var = result.image[..., 0], result.variance[..., 0]
    on = np.zeros((16, 16), bool)
    on[5:11, 5:11] = True
    z = np.abs(img[on] - albedo * radiance) / np.sqrt(np.maximum(var[on], 1e-30))
    assert np.all((z < 5) | (np.abs(img[on] - albedo * radiance) < 1e-6)), z.max()
    standard_error = math.sqrt(var[on].sum()) / on.sum()
    assert standard_error < 1e-2 * albedo * radiance  # a density 5 % off shows at 5 sigma or more
    assert abs(img[on].mean() - albedo * radiance) < 4 * standard_error + 1e-6, (img[on].mean(), standard_error)


# --- point and spot lights: delta lights, exact from one sample ---------------------------------------------------
LAMP = np.array([0.3, 1.2, -0.4])


def _lamp_scene(light, *, sky=None, blocker=False):
    """The Lambert ground point at the origin (albedo 0.6) seen alone, lit by ``light`` (and a constant sky)."""
    from lightprobe.emitters.envmap import EnvironmentMap

    env = EnvironmentMap.from_array(constant(sky)) if sky is not None else None
    scene = Scene(Camera([0.1, 1.2, 0.1], [0.0, 0.0, 0.0], fov=0.05, resolution=(1, 1)), env)
    scene.add(Rectangle.ground(size=40), Lambert(0.6))
    if blocker:
        scene.add(Sphere(0.5 * LAMP, 0.1), Lambert(0.5))
    scene.add_light(light)
    return scene


def _lamp_irradiance(intensity, position=LAMP):
    d = np.asarray(position)
    return intensity * d[1] / np.linalg.norm(d) / (d @ d)  # I cos(theta) / d^2


@pytest.mark.parametrize("options", [{}, {"strategy": "env"}, {"light_strategy": "area", "light_sampler": "bvh"}])
def test_a_point_light_gives_the_inverse_square_law_exactly(options):
    from lightprobe.emitters.punctual import PointLight

    result = render(_lamp_scene(PointLight(LAMP, 5.0)), RenderSettings(spp=16, seed=1, **options))
    expected = 0.6 / math.pi * _lamp_irradiance(5.0)
    np.testing.assert_allclose(result.image[0, 0], expected, rtol=1e-4)  # float32, and the pixel is ~1 mm wide
    # BSDF sampling alone never meets a delta light, and the render says so
    with pytest.warns(LightprobeWarning, match=r"1 delta light .* strategy 'brdf' takes none"):
        dark = render(_lamp_scene(PointLight(LAMP, 5.0)), RenderSettings(spp=16, seed=1, strategy="brdf"))
    assert np.all(dark.image == 0.0)
    blocked = render(_lamp_scene(PointLight(LAMP, 5.0), blocker=True), RenderSettings(spp=16, seed=1, **options))
    assert np.all(blocked.image == 0.0)


def test_a_spot_light_lights_inside_its_cone_only():
    from lightprobe.emitters.punctual import SpotLight

    def pixel(target, cone, start):
        spot = SpotLight(LAMP, target, 5.0, cone_angle=cone, falloff_start=start)
        return render(_lamp_scene(spot), RenderSettings(spp=4, seed=1)).image[0, 0, 0]

    full = 0.6 / math.pi * _lamp_irradiance(5.0)
    assert pixel([0, 0, 0], 30.0, 20.0) == pytest.approx(full, rel=1e-4)  # aimed at the point
    off = np.degrees(
        np.arccos(
            (-LAMP)
            @ (np.array([1.0, 0, 0]) - LAMP)
            / np.linalg.norm(LAMP)
            / np.linalg.norm(np.array([1.0, 0, 0]) - LAMP)
        )
    )
    assert pixel([1.0, 0, 0], off - 1.0, off - 5.0) == 0.0  # the point just outside the cone
    c, c_total, c_start = (math.cos(math.radians(a)) for a in (off, off + 5.0, off - 5.0))
    t = (c - c_total) / (c_start - c_total)  # pbrt-v4's smoothstep in the cosine, about 1/2 here
    assert pixel([1.0, 0, 0], off + 5.0, off - 5.0) == pytest.approx(full * t * t * (3 - 2 * t), rel=1e-4)


@pytest.mark.parametrize("options", [{}, {"heuristic": "balance", "n_bsdf": 2}, {"light_sampler": "uniform"}])
def test_a_point_light_takes_mis_weight_one_beside_the_sky(options):
    """rho / pi (pi L + I cos / d^2) within 4 standard errors: weighing the lamp's samples against the BSDF's
    density (which never produces its direction) would take about a fifth of its light away."""
    from lightprobe.emitters.punctual import PointLight

    result = render(_lamp_scene(PointLight(LAMP, 5.0), sky=0.5), RenderSettings(spp=16384, seed=4, **options))
    expected = 0.6 / math.pi * (math.pi * 0.5 + _lamp_irradiance(5.0))
    mean, se = result.image[0, 0, 0], math.sqrt(result.variance[0, 0, 0])
    assert se < 6e-3 * expected
    assert abs(mean - expected) < 4 * se + 1e-6, (mean, expected, se)


def test_a_constant_sky_beside_a_light_is_left_to_the_bsdf_samples_on_a_diffuse_surface():
    """A Lambert point under a constant sky with a delta sun: its material samples the compensated environment, whose
    compensated luminance max(L - mean, 0) is 0, so the selector never picks the sky there and the cosine-sampled
    BSDF samples find it alone, each with MIS weight 1 and the exact rho L (decisions.md 98): the pixel is
    rho / pi (pi L + E cos) with no variance at all.  Without compensation the sky is also light-sampled (unbiased,
    with variance).  A selector that weighed the sky one way to pick and another in the BSDF samples' weights
    would miss the closed form."""
    from lightprobe.emitters.directional import DirectionalLight

    scene = _lamp_scene(DirectionalLight(SUN_DIRECTION, 3.0), sky=0.5)
    expected = 0.6 / math.pi * (math.pi * 0.5 + 3.0 * -SUN_DIRECTION[1])
    result = render(scene, RenderSettings(spp=64, seed=2))
    assert result.stats["mis_compensation"] == "diffuse"
    np.testing.assert_allclose(result.image[0, 0], expected, rtol=1e-6)
    assert np.all(result.variance < 1e-16 * expected**2), result.variance
    plain = render(scene, RenderSettings(spp=64, seed=2, mis_compensation=False))
    assert np.all(plain.variance[0, 0] > 1e-8), plain.variance
    assert np.all(np.abs(plain.image[0, 0] - expected) < 4 * np.sqrt(plain.variance[0, 0]))


# --- directional lights: E cos theta at a Lambert point, as a delta light or as a disc ----------------------------
SUN_DIRECTION = np.array([-0.4, -1.0, 0.3]) / np.linalg.norm([-0.4, -1.0, 0.3])  # the way its light travels


@pytest.mark.parametrize("options", [{}, {"strategy": "env"}, {"light_sampler": "uniform"}])
def test_a_delta_directional_light_gives_e_cos_exactly(options):
    """rho / pi E cos(theta) at the ground point, exactly (a delta light: one direction, pdf 1); BSDF sampling alone
    never meets it; an occluder on its one direction takes all of it."""
    from lightprobe.emitters.directional import DirectionalLight

    sun = DirectionalLight(SUN_DIRECTION, 3.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LightprobeWarning)  # light samples reach it: no warning
        result = render(_lamp_scene(sun), RenderSettings(spp=16, seed=1, **options))
    expected = 0.6 / math.pi * 3.0 * -SUN_DIRECTION[1]
    np.testing.assert_allclose(result.image[0, 0], expected, rtol=1e-4)
    # BSDF sampling alone never meets it, and the render says so (a warning: the laboratory does it on purpose)
    with pytest.warns(LightprobeWarning, match=r"1 delta light \(point, spot .* strategy 'brdf' takes none"):
        assert np.all(render(_lamp_scene(sun), RenderSettings(spp=16, seed=1, strategy="brdf")).image == 0.0)
    with pytest.warns(LightprobeWarning, match=r"lights nothing .* reach it, and env_samples = 0 takes none"):
        render(_lamp_scene(sun), RenderSettings(spp=1, n_env=0, n_bsdf=1))
    scene = _lamp_scene(sun)
    scene.add(Sphere(-1.5 * SUN_DIRECTION, 0.2), Lambert(0.5))
    assert np.all(render(scene, RenderSettings(spp=16, seed=1, **options)).image == 0.0)


@pytest.mark.parametrize("strategy", ["mis", "env", "brdf"])
@pytest.mark.parametrize("angle", [0.53, 30.0])
def test_a_suns_disc_gives_e_cos_with_every_strategy(strategy, angle):
    """A disc of uniform radiance fully above the horizon gives the point E cos(theta) (Lambert's law for a
    spherical cap), however it is sampled: light samples in the cone, BSDF samples that escape into it, or both
    under MIS beside a constant sky; within 4 standard errors.  (BSDF sampling alone finds a 30-degree disc only:
    a half-degree sun is 6e-5 of the hemisphere.)"""
    from lightprobe.emitters.directional import DirectionalLight

    if strategy == "brdf" and angle < 1.0:
        pytest.skip("BSDF sampling alone all but never meets a half-degree sun")
    sun = DirectionalLight(SUN_DIRECTION, 3.0, angle=angle)
    result = render(_lamp_scene(sun, sky=0.25), RenderSettings(spp=16384, seed=5, strategy=strategy))
    expected = 0.6 / math.pi * (3.0 * -SUN_DIRECTION[1] + math.pi * 0.25)
    mean, se = result.image[0, 0, 0], math.sqrt(result.variance[0, 0, 0])
    assert abs(mean - expected) < 4 * se + 1e-6, (mean, expected, se)
    assert se < 0.02 * expected
