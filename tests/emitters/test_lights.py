"""The one light contract (emitters/lights.py): every kind of the light table sampled, weighed and evaluated through
the same functions; the directional light's cone against its own pdf; its errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.analysis import chi2
from lightprobe.emitters.area import AreaLight
from lightprobe.emitters.directional import DirectionalLight
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.kinds import KINDS
from lightprobe.emitters.lights import escaped_batch, light_arrays, pdf_batch, sample_batch
from lightprobe.emitters.procedural import sky_with_sun
from lightprobe.emitters.punctual import PointLight, SpotLight
from lightprobe.emitters.sun import SunLight
from lightprobe.errors import ParameterError
from lightprobe.geometry.frame import frame_matrix

RNG = np.random.default_rng(11)
POINT = np.array([0.2, 0.0, -0.3])
NORMAL = np.array([0.0, 1.0, 0.0])
SUN = DirectionalLight([-0.3, -1.0, 0.2], [3.0, 2.8, 2.5], angle=20.0)


def _one_of_each():
    """A light of every kind of the table, with the environment map it needs."""
    env = EnvironmentMap.from_array(sky_with_sun(64, 32, sun_diameter_deg=8.0))
    lights = {
        "rectangle": AreaLight.rectangle([-0.5, 2.0, -0.5], [1, 0, 0], [0, 0, 1], 3.0),
        "sphere": AreaLight.sphere([1.0, 2.0, 0.0], 0.4, 2.0),
        "triangle": AreaLight.triangle([0, 2.5, 0], [1, 2.5, 0], [0, 2.5, 1], 4.0),  # facing down
        "point": PointLight([0.0, 2.0, 1.0], 5.0),
        "spot": SpotLight([0.0, 3.0, 0.0], [0.0, 0.0, 0.0], 6.0, cone_angle=40.0),
        "directional": SUN,
        "delta directional": DirectionalLight([0.0, -1.0, -1.0], 2.0),
        "sun": SunLight([0.3, 1.0, -0.2], turbidity=3.0),
    }
    return lights, env


def test_every_kind_of_the_table_goes_through_the_contract():
    """Each kind: unit directions, finite radiance, a positive density that pdf() gives back for the sampled
    direction (0 for a delta light, whose flag is set), a distance for bounded lights and none for infinite
    ones."""
    lights, env = _one_of_each()
    seen = set()
    for name, light in lights.items():
        table = light_arrays([light])
        seen.add(light.kind)
        delta = name in ("point", "spot", "delta directional")
        _check_kind(table, 0, env=None, delta=delta, infinite=KINDS[light.kind].infinite)
    table = light_arrays([], environment=True)
    _check_kind(table, 0, env=env, delta=False, infinite=True)
    seen.add("environment")
    assert seen == set(KINDS), set(KINDS) - seen  # a new kind must join this test


def _check_kind(table, row, *, env, delta, infinite):
    n = 4000
    u = RNG.random((n, 2))
    out = sample_batch(table, row, np.tile(POINT, (n, 1)), np.tile(NORMAL, (n, 1)), u, env=env)
    direction, distance, radiance, pdf, flag = out[:, :3], out[:, 3], out[:, 4:7], out[:, 7], out[:, 8]
    live = pdf > 0
    assert live.mean() > 0.5
    np.testing.assert_allclose(np.linalg.norm(direction[live], axis=1), 1.0, atol=1e-9)
    assert np.all(np.isfinite(radiance)) and np.all(radiance >= 0) and radiance.max() > 0
    assert np.all(flag == (1.0 if delta else 0.0))
    assert np.all(np.isinf(distance[live]) == infinite)
    back = pdf_batch(table, row, np.tile(POINT, (n, 1)), np.tile(NORMAL, (n, 1)), direction, env=env)
    if delta:
        assert np.all(pdf[live] == 1.0) and np.all(back == 0.0)
    else:
        np.testing.assert_allclose(back[live], pdf[live], rtol=1e-9)


@pytest.mark.parametrize("angle", [0.53, 5.0, 20.0, 120.0])
def test_a_directional_lights_cone_matches_its_pdf(angle):
    """Chi-square of the cone's samples against the light's own pdf (a quarter-degree sun to a 120-degree sky
    patch), the pdf integrating to 1, and the radiance L = E / (pi sin^2 alpha)."""
    light = DirectionalLight([0.2, -1.0, 0.4], 3.0, angle=angle)
    table = light_arrays([light])
    n = 200_000
    out = sample_batch(table, 0, np.zeros((n, 3)), np.tile(NORMAL, (n, 1)), RNG.random((n, 2)))
    frame = frame_matrix(-light.direction)

    def density(v):
        return pdf_batch(table, 0, np.zeros((v.shape[0], 3)), np.tile(NORMAL, (v.shape[0], 1)), v)

    # rings inside the cone, the last one a hair past its rim (a sample on the rim may round either way), then
    # the rest of the sphere: the pdf is constant in every cell but that one
    rim = math.radians(angle) / 2 * (1 + 1e-6)
    edges = np.concatenate([np.linspace(0.0, rim, 49), np.linspace(rim, math.pi, 17)[1:]])
    result = chi2.spherical_test(
        out[:, :3], density, frame=frame, theta_edges=edges, phi_edges=np.linspace(0, 2 * np.pi, 65), test_count=4
    )
    assert result.passed, str(result)
    assert result.pdf_integral == pytest.approx(1.0, abs=2e-3)
    alpha = math.radians(angle) / 2
    np.testing.assert_allclose(out[:, 4], 3.0 / (math.pi * math.sin(alpha) ** 2), rtol=1e-12)
    np.testing.assert_allclose(out[:, 7], 1.0 / (2 * math.pi * (1 - math.cos(alpha))), rtol=1e-9)


def test_a_cone_of_the_wrong_width_fails_the_chi_square_test():
    """Negative control: the samples of a 5-degree sun against the pdf of a 5.5-degree one."""
    wide = light_arrays([DirectionalLight([0.2, -1.0, 0.4], 3.0, angle=5.5)])
    narrow = light_arrays([DirectionalLight([0.2, -1.0, 0.4], 3.0, angle=5.0)])
    n = 200_000
    out = sample_batch(narrow, 0, np.zeros((n, 3)), np.tile(NORMAL, (n, 1)), RNG.random((n, 2)))
    frame = frame_matrix(np.array([-0.2, 1.0, -0.4]) / np.linalg.norm([-0.2, 1.0, -0.4]))

    def density(v):
        return pdf_batch(wide, 0, np.zeros((v.shape[0], 3)), np.tile(NORMAL, (v.shape[0], 1)), v)

    rim = math.radians(5.5) / 2 * (1 + 1e-6)
    edges = np.concatenate([np.linspace(0.0, rim, 49), np.linspace(rim, math.pi, 17)[1:]])
    assert not chi2.spherical_test(out[:, :3], density, frame=frame, theta_edges=edges).passed


def test_rays_that_escape_see_the_environment_and_the_suns_disc():
    """escaped_radiance sums every infinite light: the map's radiance everywhere, plus L inside the sun's cone."""
    env = EnvironmentMap.from_array(np.full((8, 16, 3), 0.5, np.float32))
    table = light_arrays([SUN], environment=True)
    inside = -SUN.direction
    outside = np.array([0.0, 1.0, 0.0])
    seen = escaped_batch(table, np.array([inside, outside]), env=env)
    np.testing.assert_allclose(seen[0], 0.5 + SUN.radiance, rtol=1e-6)
    np.testing.assert_allclose(seen[1], 0.5, rtol=1e-6)


def test_escaping_rays_see_only_the_infinite_rows_that_close_the_table():
    """escaped_radiance finds the infinite lights from the table's end: bounded lights before them (a bright
    rectangle, a point and a spot light here) add nothing, however many there are."""
    lights, env = _one_of_each()
    bounded = [lights[k] for k in ("rectangle", "sphere", "triangle", "point", "spot")]
    table = light_arrays([*bounded, SUN], environment=True)
    alone = light_arrays([SUN], environment=True)
    dirs = np.array([-SUN.direction, [0.0, 1.0, 0.0], [0.6, -0.8, 0.0]])
    np.testing.assert_array_equal(escaped_batch(table, dirs, env=env), escaped_batch(alone, dirs, env=env))
    assert escaped_batch(table, dirs, env=env)[0].sum() > escaped_batch(table, dirs, env=env)[1].sum()
    no_infinite = light_arrays(bounded)
    np.testing.assert_array_equal(escaped_batch(no_infinite, dirs, env=env), 0.0)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: DirectionalLight([0, 0, 0], 1.0), "direction"),
        (lambda: DirectionalLight([0, -1], 1.0), "direction"),
        (lambda: DirectionalLight([0, -1, 0], -1.0), "irradiance"),
        (lambda: DirectionalLight([0, -1, 0], "bright"), "irradiance"),
        (lambda: DirectionalLight([0, -1, 0], 1.0, angle=180.0), "angle"),
        (lambda: DirectionalLight([0, -1, 0], 1.0, angle=-1.0), "angle"),
    ],
)
def test_bad_directional_lights_are_one_clear_error(make, message):
    with pytest.raises(ParameterError, match=message):
        make()


def test_the_sidecar_counts_every_kind_of_light_by_its_flags():
    """A scene with two rectangle lights, a sphere light, an emissive mesh of three faces, two point lights, a spot
    light, a directional light and a map: the render's statistics count 6 area lights (the rows rays can hit), 2
    point, 1 spot and 1 directional light, the environment, 11 rows in all (point and spot lights were counted as
    area lights by their codes' order)."""
    from lightprobe.bsdfs import Lambert
    from lightprobe.geometry.camera import Camera
    from lightprobe.geometry.mesh import TriangleMesh
    from lightprobe.geometry.shapes import Rectangle, Sphere
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.scene import Scene

    image = sky_with_sun(32, 16, sun_elevation_deg=40.0, sun_azimuth_deg=30.0, sun_diameter_deg=5.0)
    scene = Scene(Camera([0, 1, 4], [0, 0, 0], resolution=(8, 6)), EnvironmentMap.from_array(image))
    scene.add(Rectangle([-4, 0, -4], [0, 0, 8], [8, 0, 0]), Lambert(0.5))
    for x in (-1.0, 1.0):
        scene.add(Rectangle([x, 2, -0.5], [0, 0, 0.4], [0.4, 0, 0]), emission=3.0)
    scene.add(Sphere([0, 2, 0], 0.1), emission=5.0)
    faces = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 2]])
    vertices = np.array([[0, 3, 0], [1, 3, 0], [1, 3, 1], [0, 3, 1], [2, 3, 0.5]], np.float64)
    scene.add(TriangleMesh.from_arrays(vertices, faces), emission=2.0, two_sided=True)
    scene.add_light(PointLight([0.5, 1.5, 0.5], 2.0))
    scene.add_light(PointLight([-0.5, 1.5, 0.5], 2.0))
    scene.add_light(SpotLight([0, 2.5, 1], [0, 0, 0], 4.0))
    scene.add_light(DirectionalLight([0.3, 1.0, 0.2], 1.0))
    stats = render(scene, RenderSettings(spp=1, seed=0)).stats
    counts = {key: stats[key] for key in ("lights", "area_lights", "point_lights", "spot_lights", "directional_lights")}
    assert counts == {"lights": 11, "area_lights": 6, "point_lights": 2, "spot_lights": 1, "directional_lights": 1}
    assert stats["environment"] is True
    # the same rows asked for by name and by flag, as code outside emitters/ asks
    from lightprobe.emitters.kinds import area_rows, rows_of

    kinds = scene.light_table().kind
    by_name = {name: int(rows_of(kinds, name).sum()) for name in ("rectangle", "sphere", "triangle", "point", "spot")}
    assert by_name == {"rectangle": 2, "sphere": 1, "triangle": 3, "point": 2, "spot": 1}
    assert area_rows(kinds).tolist() == [True] * 6 + [False] * 5


def test_no_kind_is_known_by_its_number_outside_emitters():
    """Code outside ``emitters/`` asks for a light's kind by name or flag (``rows_of``, ``area_rows``,
    ``lights.is_delta``, ``lights.is_positional``), never through the ``LIGHT_*`` numbers, so that a new kind is
    added in one place (issue 58)."""
    import re
    from pathlib import Path

    import lightprobe
    from lightprobe.emitters import kinds

    numbers = [name for name in kinds.__all__ if name.startswith("LIGHT_")]
    assert len(numbers) == len(KINDS)
    pattern = re.compile(r"\b(" + "|".join(numbers) + r")\b")
    package = Path(lightprobe.__file__).parent
    found = [
        f"{path.relative_to(package)}:{number + 1}: {line.strip()}"
        for path in sorted(package.rglob("*.py"))
        if path.parent.name != "emitters"
        for number, line in enumerate(path.read_text().splitlines())
        if pattern.search(line)
    ]
    assert found == []


def test_kinds_are_tested_by_their_flags_never_by_their_order():
    """The compiled flag tests read tables built from KINDS, so a new kind with a flag is counted everywhere the
    flag is asked; and no code in the package compares a kind's number by its order (``kind >= LIGHT_POINT`` took
    a new kind numbered after the point light for a light without a surface, whatever it was)."""
    import re
    from pathlib import Path

    import lightprobe
    from lightprobe.emitters import kinds

    for kind in KINDS.values():
        assert kinds.is_area_kind.py_func(kind.code) == kind.area, kind.name
        assert kinds.is_infinite_kind.py_func(kind.code) == kind.infinite, kind.name
        assert kinds.is_positional_kind.py_func(kind.code) == (kind.delta and not kind.infinite), kind.name
    codes = np.array([kind.code for kind in KINDS.values()])
    assert kinds.flag_rows(codes, "infinite").tolist() == [kind.infinite for kind in KINDS.values()]
    assert kinds.area_rows(codes).tolist() == [kind.area for kind in KINDS.values()]
    ordered = re.compile(r"[<>]=?\s*LIGHT_[A-Z]+\b|\bLIGHT_[A-Z]+\s*[<>]")
    package = Path(lightprobe.__file__).parent
    found = [
        f"{path.relative_to(package)}:{number + 1}: {line.strip()}"
        for path in sorted(package.rglob("*.py"))
        for number, line in enumerate(path.read_text().splitlines())
        if ordered.search(line)
    ]
    assert found == []


def test_the_dispatchers_are_written_from_the_kinds_table():
    """Each kind's module has the contract (row_sample, row_pdf, and row_radiance for infinite kinds), and each
    dispatcher tests every kind's code once and calls its module: a new kind is a module and a line of KINDS."""
    import importlib
    import re

    from lightprobe.emitters import lights

    for kind in KINDS.values():
        module = importlib.import_module(f"lightprobe.emitters.{kind.module}")
        names = ("row_sample", "row_pdf") + (("row_radiance",) if kind.infinite else ())
        assert all(callable(getattr(module, name, None)) for name in names), kind.name
    for function, infinite_only in (("row_sample", False), ("row_pdf", False), ("row_radiance", True)):
        source = lights.dispatch_source(function, "dispatch")
        wanted = [k for k in KINDS.values() if k.infinite or not infinite_only]
        tested = [int(code) for code in re.findall(r"kind == (\d+)", source)]
        last_module = wanted[-1].module  # the last module's call is unconditional
        assert sorted(tested) == sorted(k.code for k in wanted if k.module != last_module), function
        for kind in wanted:
            assert f"return {kind.module}.{function}(" in source, (function, kind.name)
