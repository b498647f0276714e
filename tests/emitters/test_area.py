"""Area emitters through their interface: chi-square of every strategy against its own pdf at several reference
points, the pdf integrates to one, sample() and pdf() agree, and irradiance matches closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.analysis import chi2
from lightprobe.emitters.area import STRATEGIES, AreaLight
from lightprobe.geometry.frame import frame_matrix

# A 1 x 0.6 rectangle and a triangle in the plane y = 2 facing down (-Y), and a sphere of radius 0.4 at height 2.
RECT = AreaLight.rectangle([-0.5, 2.0, -0.3], [0.0, 0.0, 0.6], [1.0, 0.0, 0.0], 3.0)  # (+Z) x (+X) = +Y: faces up
RECT_DOWN = AreaLight.rectangle([-0.5, 2.0, -0.3], [1.0, 0.0, 0.0], [0.0, 0.0, 0.6], 3.0)  # faces down
TRIANGLE = AreaLight.triangle([-0.5, 2.0, -0.3], [0.5, 2.0, -0.3], [0.1, 2.0, 0.5], 2.0)  # winding: faces down
SPHERE = AreaLight.sphere([0.2, 2.0, 0.1], 0.4, 1.5)
LIGHTS = {"rectangle": RECT_DOWN, "triangle": TRIANGLE, "sphere": SPHERE}

# Reference points (position, normal): near, far, where the rectangle is just small enough to be sampled by
# area (decisions.md 119), grazing (the light near the horizon of the receiver), just
# above the plane of the light (grazing from the light's side), inside the plane, and behind a one-sided light.
POINTS = {
    "near": ([0.1, 1.5, 0.0], [0.0, 1.0, 0.0]),
    "far": ([3.0, -20.0, 2.0], [0.0, 1.0, 0.0]),
    "small": ([0.3, -3.0, 0.2], [0.0, 1.0, 0.0]),  # the rectangle at 0.23 of the distance: area-sampled
    "grazing": ([4.0, 1.8, 0.0], [0.0, 1.0, 0.0]),
    "light-plane-grazing": ([3.0, 1.9, 0.2], [-1.0, 0.0, 0.0]),  # 2 degrees below the light's plane
}


def _frame_toward(light: AreaLight, p):
    """Chi-square frame with its axis toward the light's centre (the lobe of a small light sits on the axis)."""
    g = light.geom
    centre = {"rectangle": g[0:3] + 0.5 * (g[3:6] + g[6:9]), "triangle": (g[0:3] + g[3:6] + g[6:9]) / 3}.get(
        light.kind, g[0:3]
    )
    d = centre - np.asarray(p, dtype=float)
    return frame_matrix(d / np.linalg.norm(d))


def _chi2(light, strategy, p, n, samples=200_000, seed=1):
    u = np.random.default_rng(seed).random((samples, 2))
    s = light.sample_li(p, n, u, strategy=strategy)
    valid = s.pdf > 0

    def density(v):
        return light.pdf_li(p, n, v, strategy=strategy)

    frame = _frame_toward(light, p)
    edges = chi2.equal_mass_theta_edges(density, 48, frame=frame)
    return chi2.spherical_test(
        s.direction[valid],
        density,
        frame=frame,
        theta_edges=edges,
        phi_edges=np.linspace(0, 2 * np.pi, 65),
        test_count=len(LIGHTS) * len(POINTS) * 2 + len(LIGHTS) * 2,
    ), s


@pytest.mark.parametrize("point", list(POINTS))
@pytest.mark.parametrize("strategy", ["area", "solid-angle"])
@pytest.mark.parametrize("kind", list(LIGHTS))
def test_light_sampling_matches_its_pdf(kind, strategy, point):
    light = LIGHTS[kind]
    p, n = POINTS[point]
    result, s = _chi2(light, strategy, p, n)
    assert result.passed, str(result)
    # the pdf integrates to one over the sphere, and sample() reports pdf() at the sampled direction
    assert result.pdf_integral == pytest.approx(1.0, abs=2e-3), result.pdf_integral
    valid = s.pdf > 0
    assert valid.mean() > 0.999
    np.testing.assert_allclose(light.pdf_li(p, n, s.direction[valid], strategy=strategy), s.pdf[valid], rtol=1e-9)


@pytest.mark.parametrize("strategy", ["hemisphere", "cosine"])
@pytest.mark.parametrize("kind", list(LIGHTS))
def test_hemisphere_strategies_match_their_pdf(kind, strategy):
    light = LIGHTS[kind]
    p, n = POINTS["near"]
    u = np.random.default_rng(2).random((200_000, 2))
    s = light.sample_li(p, n, u, strategy=strategy)
    frame = frame_matrix(np.asarray(n, dtype=float))

    def density(v):
        return light.pdf_li(p, n, v, strategy=strategy)

    result = chi2.spherical_test(s.direction, density, frame=frame)
    assert result.passed and result.pdf_integral == pytest.approx(1.0, abs=1e-3), str(result)
    np.testing.assert_allclose(light.pdf_li(p, n, s.direction, strategy=strategy), s.pdf, rtol=1e-12)
    # only directions that hit the light carry its radiance
    hits = np.isfinite(s.distance)
    assert 0 < hits.mean() < 1 and np.all(s.radiance[~hits] == 0)


@pytest.mark.parametrize("strategy", list(STRATEGIES))
@pytest.mark.parametrize("kind", ["rectangle", "triangle"])
def test_nothing_is_sampled_behind_or_in_the_plane_of_a_one_sided_light(kind, strategy):
    light = LIGHTS[kind]
    u = np.random.default_rng(3).random((2000, 2))
    for p, n in (([0.0, 2.5, 0.0], [0.0, -1.0, 0.0]), ([3.0, 2.0, 0.0], [-1.0, 0.0, 0.0])):
        s = light.sample_li(p, n, u, strategy=strategy)
        assert np.all(s.radiance == 0) and np.all(np.isfinite(s.pdf))
        assert np.all(light.eval(p, s.direction) == 0)
        if strategy in ("area", "solid-angle"):
            assert np.all(s.pdf == 0) and np.all(light.pdf_li(p, n, s.direction, strategy=strategy) == 0)


def test_two_sided_lights_emit_from_the_back():
    back = AreaLight.rectangle([-0.5, 2.0, -0.3], [0.0, 0.0, 0.6], [1.0, 0.0, 0.0], 3.0, two_sided=True)
    s = back.sample_li([0.0, 1.0, 0.0], [0.0, 1.0, 0.0], np.full((10, 2), 0.5), strategy="area")
    np.testing.assert_allclose(s.radiance, 3.0)
    assert np.all(RECT.sample_li([0.0, 1.0, 0.0], [0.0, 1.0, 0.0], np.full((10, 2), 0.5)).radiance == 0)


# --- closed forms ----------------------------------------------------------------------------------------------------
def polygon_irradiance(p, n, vertices, radiance):
    """Lambert's 1760 formula for a uniform polygon (Baum et al. 1989): E = L/2 sum_i Theta_i (n . Gamma_i)."""
    v = [(np.asarray(q, float) - p) / np.linalg.norm(np.asarray(q, float) - p) for q in vertices]
    total = 0.0
    for a, b in zip(v, v[1:] + v[:1], strict=True):
        g = np.cross(a, b)
        total += math.acos(np.clip(a @ b, -1, 1)) * (n @ (g / np.linalg.norm(g)))
    return 0.5 * abs(total) * radiance


def _estimate(light, p, n, strategy, samples, seed):
    u = np.random.default_rng(seed).random((samples, 2))
    s = light.sample_li(p, n, u, strategy=strategy)
    cos = np.clip(s.direction @ n, 0, None)
    ok = s.pdf > 0
    value = np.zeros(samples)
    value[ok] = s.radiance[ok, 0] * cos[ok] / s.pdf[ok]
    return value.mean(), value.std() / math.sqrt(samples)


RECEIVERS = [
    ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),  # below the centre, facing it
    ([0.7, 1.0, 0.4], [0.0, 1.0, 0.0]),  # near and off-axis
    ([0.3, -6.0, 0.0], [0.0, 1.0, 0.0]),  # far
    ([0.0, 1.0, 0.0], [0.6, 0.8, 0.0]),  # tilted
    ([1.5, 1.2, 0.0], [-0.8, 0.6, 0.0]),  # tilted toward the light from the side
]


@pytest.mark.parametrize("receiver", range(len(RECEIVERS)))
@pytest.mark.parametrize("strategy", list(STRATEGIES))
def test_rectangle_irradiance_matches_the_polygon_form_factor(strategy, receiver):
    p, n = (np.asarray(x, float) for x in RECEIVERS[receiver])
    g = RECT_DOWN.geom
    corners = [g[0:3], g[0:3] + g[3:6], g[0:3] + g[3:6] + g[6:9], g[0:3] + g[6:9]]
    if n[1] != 1.0:  # the whole rectangle must be above the tilted horizon for the formula
        assert all((c - p) @ n > 0 for c in corners)
    expected = polygon_irradiance(p, n, corners, 3.0)
    mean, se = _estimate(RECT_DOWN, p, n, strategy, 400_000, seed=10 + receiver)
    assert abs(mean - expected) < 4 * se + 1e-12 * expected, (mean, expected, se)


@pytest.mark.parametrize("distance", [0.6, 1.0, 3.0, 30.0])
@pytest.mark.parametrize("strategy", list(STRATEGIES))
def test_sphere_irradiance_on_axis_is_pi_l_sin2(strategy, distance):
    """On the axis, facing the sphere: E = pi L sin^2(alpha), sin(alpha) = r / d (also under a tilt that keeps the
    sphere above the horizon: E = pi L sin^2(alpha) cos(tilt))."""
    r, radiance = 0.4, 1.5
    light = AreaLight.sphere([0.0, 0.0, 0.0], r, radiance)
    p = np.array([0.0, -distance, 0.0])
    for tilt in (0.0, 0.3):
        if math.asin(r / distance) + tilt >= math.pi / 2:
            continue
        n = np.array([math.sin(tilt), math.cos(tilt), 0.0])
        expected = math.pi * radiance * (r / distance) ** 2 * math.cos(tilt)
        mean, se = _estimate(light, p, n, strategy, 400_000, seed=int(distance * 10))
        if strategy == "solid-angle":  # uniform over the cone: exact on the axis up to the cosine's variation
            assert se < 0.02 * expected
        assert abs(mean - expected) < 4 * se + 1e-9 * expected, (tilt, mean, expected, se)


@pytest.mark.parametrize(("distance", "radius"), [(0.41, 0.4), (3.0, 0.4), (1000.0, 0.01)])
def test_a_sphere_sample_is_where_its_direction_first_meets_the_sphere(distance, radius):
    """Solid-angle samples of a sphere light (its point found from the cone's angle, no ray traced): the distance
    is the nearer root of the ray-sphere equation along the sampled direction, the radiance the light's for every
    sample, the cone's rim (u1 = 1) included, near, far and 1000 radii away."""
    centre = np.array([0.3, 2.0, -0.2])
    light = AreaLight.sphere(centre, radius, 1.5)
    m = 20_000
    u = np.random.default_rng(11).random((m, 2))
    u[:500, 1] = 1.0  # on the rim
    u[500:1000, 1] = 0.0  # toward the centre
    p = centre - np.array([0.0, distance, 0.0])
    s = light.sample_li(np.tile(p, (m, 1)), np.tile([0.0, 1.0, 0.0], (m, 1)), u)
    np.testing.assert_array_equal(s.radiance, np.full((m, 3), 1.5))
    oc = p - centre
    b = s.direction @ oc
    c = oc @ oc - radius * radius
    near = -b - np.sqrt(np.maximum(b * b - c, 0.0))
    np.testing.assert_allclose(s.distance[500:], near[500:], rtol=1e-9, atol=1e-9 * distance)
    # the rim, where the roots meet (and their formula loses half its digits): the tangent distance sqrt(d^2 - r^2)
    np.testing.assert_allclose(s.distance[:500], math.sqrt(distance**2 - radius**2), rtol=1e-7)


def test_triangle_irradiance_matches_the_polygon_form_factor():
    p, n = np.array([0.05, 0.8, 0.0]), np.array([0.0, 1.0, 0.0])
    g = TRIANGLE.geom
    expected = polygon_irradiance(p, n, [g[0:3], g[3:6], g[6:9]], 2.0)
    for strategy in STRATEGIES:
        mean, se = _estimate(TRIANGLE, p, n, strategy, 400_000, seed=5)
        assert abs(mean - expected) < 4 * se, (strategy, mean, expected, se)


def test_the_environment_map_honours_the_same_contract():
    from lightprobe.emitters.envmap import EnvironmentMap
    from lightprobe.emitters.procedural import sky_with_sun

    env = EnvironmentMap.from_array(sky_with_sun(64, 32, sun_diameter_deg=8.0))
    p, n = np.zeros((500, 3)), np.tile([0.0, 1.0, 0.0], (500, 1))
    s = env.sample_li(p, n, np.random.default_rng(4).random((500, 2)))
    assert np.all(np.isinf(s.distance)) and not s.delta
    np.testing.assert_allclose(env.pdf_li(p, n, s.direction), s.pdf, rtol=1e-12)
    np.testing.assert_allclose(env.eval(s.direction), s.radiance)


@pytest.mark.parametrize("kind", ["rectangle", "triangle"])
def test_a_planar_light_small_seen_from_the_receiver_is_sampled_by_area(kind):
    """Solid-angle sampling of a rectangle or triangle whose extent is at most SMALL_EXTENT x the distance to its
    centre falls back to area sampling (decisions.md 119): just beyond that distance every sample's density is
    |x - x'|^2 / (|cos theta'| A), just within it 1 / Omega, the same for every sample; pdf() agrees either way."""
    from lightprobe.emitters.area import SMALL_EXTENT

    light = LIGHTS[kind]
    g = light.geom
    if kind == "rectangle":
        centre, extent = g[0:3] + 0.5 * (g[3:6] + g[6:9]), math.hypot(np.linalg.norm(g[3:6]), np.linalg.norm(g[6:9]))
    else:
        centre = (g[0:3] + g[3:6] + g[6:9]) / 3
        extent = math.hypot(np.linalg.norm(g[3:6] - g[0:3]), np.linalg.norm(g[6:9] - g[0:3]))
    area = float(light.area)
    below = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])  # below the downward-facing light
    normal = [0.0, 1.0, 0.0]
    u = np.random.default_rng(7).random((4000, 2))
    for factor, small in ((1.02, True), (0.98, False)):
        p = centre + below * extent / SMALL_EXTENT * factor
        s = light.sample_li(p, normal, u, strategy="solid-angle")
        assert (s.pdf > 0).all()
        np.testing.assert_allclose(light.pdf_li(p, normal, s.direction, strategy="solid-angle"), s.pdf, rtol=1e-9)
        cos_light = np.abs(s.direction @ g[9:12])
        by_area = s.distance**2 / (cos_light * area)
        if small:
            np.testing.assert_allclose(s.pdf, by_area, rtol=1e-9)
        else:  # uniform in solid angle: one density, which area sampling's would not be
            np.testing.assert_allclose(s.pdf, s.pdf[0], rtol=1e-9)
            assert np.ptp(by_area) > 0.05 * s.pdf[0]


def test_the_spherical_rectangles_solid_angle_is_its_two_triangles():
    """Urena's four internal angles (atan2 of each corner's products, decisions.md 91) against the solid angles of the
    rectangle's two triangles (Van Oosterom and Strackee), from receivers near, far, grazing its plane and far off
    its normal, for rectangles from 1 mm to 10 m: agreement to 1e-9 relative, or 1e-14 sr where the four angles'
    sum, less 2 pi, cancels (the tiny solid angles of far, grazing receivers: the previous formula, with normalised
    cross products, erred alike, 4e-9 relative at 9e-8 sr)."""
    from lightprobe.emitters.area import _rect_frame, _rect_solid_angle, _triangle_directions, _triangle_solid_angle

    rng = np.random.default_rng(91)
    worst = 0.0
    for _ in range(400):
        size = 10.0 ** rng.uniform(-3.0, 1.0)
        eu = rng.normal(size=3)
        eu *= size * rng.uniform(0.2, 1.0) / np.linalg.norm(eu)
        ev = np.cross(eu, rng.normal(size=3))
        ev *= size * rng.uniform(0.2, 1.0) / np.linalg.norm(ev)
        origin = rng.normal(size=3)
        n = np.cross(eu, ev) / np.linalg.norm(np.cross(eu, ev))
        offset = rng.normal(size=3) * size * 10.0 ** rng.uniform(-1.0, 2.0)
        p = origin + 0.5 * (eu + ev) + offset
        if abs((p - origin) @ n) < 1e-6 * size:  # in the plane: no spherical rectangle
            continue
        g = np.concatenate([origin, eu, ev, n, np.zeros(3)])
        omega, terms = _rect_solid_angle(_rect_frame(p[0], p[1], p[2], g))
        corners = [origin, origin + eu, origin + eu + ev, origin + ev]
        halves = 0.0
        for a, b, c in ((corners[0], corners[1], corners[2]), (corners[0], corners[2], corners[3])):
            tri = np.concatenate([a, b, c])
            halves += _triangle_solid_angle(*_triangle_directions(p[0], p[1], p[2], tri))
        assert omega > 0.0 and len(terms) == 6
        worst = max(worst, abs(omega - halves) / (halves + 1e-5))
    assert worst < 1e-9, worst
