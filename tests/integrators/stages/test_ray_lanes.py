"""The shape tests in lanes (integrators/stages/ray_lanes.py): the BSDF rays' nearest analytic hits and the shadow
rays, to lights' sampled points and to infinity, against the scalar stages, slot for slot."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.demo import blob_mesh
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.kinds import LIGHT_RECT, LIGHT_SPHERE, LIGHT_TRIANGLE
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.intersect import ANALYTIC_ERROR, MISS, RECT, SPHERE
from lightprobe.geometry.mesh import TriangleMesh
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.integrators import pipeline
from lightprobe.integrators.techniques import (
    BLOCKED,
    NONE,
    SLOT_BSDF,
    SLOT_HEMI,
    SLOT_LIGHT,
    SLOT_NONE,
    TEST_ANALYTIC,
    TEST_MESH,
    VISIBLE,
)
from lightprobe.scene import Scene

from . import records

HIT_FIELDS = ("ray_o", "hit_t", "hit_kind", "hit_index", "hit_prim", "hit_b1", "hit_b2", "hit_mesh")


def _scene(meshes=True, spheres=True):
    """Occluders (``_occluders``) and three kinds of area light: a rectangle, a sphere and two triangles."""
    sc = _occluders(Scene(Camera([0, 1, 5], [0, 0, 0])), meshes, spheres)
    sc.add(Rectangle([-1.0, 2.4, -1.0], [0.0, 0.0, 1.2], [1.2, 0.0, 0.0]), emission=5.0)  # facing down
    sc.add(Sphere([1.4, 1.3, -0.6], 0.2), emission=20.0)
    triangles = np.array([[1.0, 2.2, 1.0], [2.0, 2.2, 1.0], [1.5, 2.2, 2.0], [-2.5, 1.5, 1.0], [-2.5, 1.5, 2.0],
                          [-2.0, 2.5, 1.5]])  # fmt: skip
    sc.add(TriangleMesh.from_arrays(triangles, [[0, 2, 1], [3, 4, 5]], smooth=False), emission=3.0, two_sided=True)
    return sc


def _points(n_samples, seed):
    """Shading points on and above the ground, half of them on the first sphere, with their normals and error
    bounds."""
    rng = np.random.default_rng(seed)
    point = np.column_stack(
        [rng.uniform(-3, 3, n_samples), rng.uniform(0, 1.5, n_samples), rng.uniform(-3, 3, n_samples)]
    )
    point[::3, 1] = 0.0
    normal = rng.normal(size=(n_samples, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    normal[::3] = [0.0, 1.0, 0.0]
    on_sphere = rng.normal(size=(n_samples // 2, 3))
    on_sphere /= np.linalg.norm(on_sphere, axis=1)[:, None]
    point[1::2] = np.array([-1.5, 0.5, 0.0]) + 0.5 * on_sphere
    normal[1::2] = on_sphere
    return point, normal, _errors(point, normal)


def _errors(point, normal):
    """Error bounds of analytic points (intersect.point_error with a shape of size 8, the ground's)."""
    return ANALYTIC_ERROR * (np.abs(point) * np.abs(normal)).sum(axis=1) + ANALYTIC_ERROR * 8.0


def _directions(n, rng):
    """Random unit directions, every seventh along an axis (the slab test's zero components)."""
    wdir = rng.normal(size=(n, 3))
    wdir[::7] = np.eye(3)[rng.integers(0, 3, wdir[::7].shape[0])] * rng.choice([-1.0, 1.0], (wdir[::7].shape[0], 1))
    return wdir / np.linalg.norm(wdir, axis=1)[:, None]


def _run(stage, scene, m, point, normal, error, **slot_arrays):
    """Stage ``stage`` over one pass of ``point.shape[0]`` camera samples of m slots; returns the slots."""
    arrays = scene.compile()
    c = records.constants(m)
    cams = records.cameras(point.shape[0], point=point, gnormal=normal, point_error=error)
    copies = {name: np.array(a) for name, a in slot_arrays.items()}  # the stage writes into its slots
    slots = records.slots(point.shape[0] * m, picks=True, bounded=True, hits=True, **copies)
    records.run(stage, records.records(c, cams, slots, scene=scene, arrays=arrays))
    return slots


@pytest.mark.parametrize(("meshes", "spheres", "m"), [(True, True, 4), (True, True, 5), (False, False, 3)])
def test_bsdf_rays_find_the_nearest_analytic_hit_as_the_scalar_stage(meshes, spheres, m):
    """Origin, nearest hit (distance, kind, shape) and whether a mesh may be nearer: the same numbers for every BSDF
    and hemisphere slot (a pass length that is not a multiple of 8, camera samples across blocks); the other slots
    untouched; scenes without meshes or occluding spheres too."""
    scene = _scene(meshes, spheres)
    rng = np.random.default_rng(m)
    point, normal, error = _points(2503, seed=m)
    n = point.shape[0] * m
    state = rng.choice([SLOT_NONE, SLOT_BSDF, SLOT_BSDF, SLOT_HEMI, SLOT_LIGHT], n).astype(np.int8)
    wdir = _directions(n, rng)
    scalar = _run("nearest_analytic", scene, m, point, normal, error, state=state, wdir=wdir)
    lanes = _run("nearest_analytic_lanes", scene, m, point, normal, error, state=state, wdir=wdir)
    for field in HIT_FIELDS:
        np.testing.assert_array_equal(getattr(lanes, field), getattr(scalar, field), err_msg=field)
    traced = (state == SLOT_BSDF) | (state == SLOT_HEMI)
    assert not np.any(lanes.hit_t[~traced]) and not np.any(lanes.hit_mesh[~traced])  # the others: not written
    kinds = lanes.hit_kind[traced]
    assert np.count_nonzero(kinds == MISS) > 300 and np.count_nonzero(kinds == RECT) > 300
    if spheres:  # without the occluding spheres, only the small sphere light is hit, and seldom
        assert np.count_nonzero(kinds == SPHERE) > 300
    assert np.all(np.isinf(lanes.hit_t[traced][kinds == MISS]))
    assert np.count_nonzero(lanes.hit_mesh[traced]) > 100  # the blobs, or the light triangles (a mesh too)


def _light_points(scene, light, rng):
    """A point on each row ``light`` of the scene's light table (rectangle, sphere or triangle)."""
    table = scene.light_table()
    g, kind = table.geom[light], table.kind[light]
    u, v = rng.uniform(size=(2, light.size))
    on_rect = g[:, 0:3] + u[:, None] * g[:, 3:6] + v[:, None] * g[:, 6:9]
    fold = u + v > 1.0
    u, v = np.where(fold, 1.0 - u, u), np.where(fold, 1.0 - v, v)
    on_triangle = (1.0 - u - v)[:, None] * g[:, 0:3] + u[:, None] * g[:, 3:6] + v[:, None] * g[:, 6:9]
    direction = _directions(light.size, rng)
    on_sphere = g[:, 0:3] + g[:, 3:4] * direction
    return np.where(
        (kind == LIGHT_RECT)[:, None], on_rect, np.where((kind == LIGHT_SPHERE)[:, None], on_sphere, on_triangle)
    )


@pytest.mark.parametrize(("meshes", "spheres", "m"), [(True, True, 4), (True, True, 5), (False, False, 3)])
def test_shadow_rays_to_lights_are_flagged_as_the_scalar_stage_does(meshes, spheres, m):
    """Shadow rays from shading points to points on rectangle, sphere and triangle lights (bounded), and unbounded
    rays (BSDF slots): blocked, to be tested against the meshes, or visible, the same flag as the scalar stage's for
    every slot flagged TEST_ANALYTIC; every other slot untouched."""
    scene = _scene(meshes, spheres)
    table = scene.light_table()
    assert set(table.kind.tolist()) == {LIGHT_RECT, LIGHT_SPHERE, LIGHT_TRIANGLE}
    rng = np.random.default_rng(10 + m)
    point, normal, error = _points(2503, seed=10 + m)
    n = point.shape[0] * m
    state = rng.choice([SLOT_LIGHT, SLOT_LIGHT, SLOT_LIGHT, SLOT_BSDF], n).astype(np.int8)
    light = rng.integers(0, table.kind.size, n)
    target = _light_points(scene, light, rng)
    toward = target - np.repeat(point, m, axis=0)
    seg = np.linalg.norm(toward, axis=1)
    wdir = np.where((state == SLOT_LIGHT)[:, None], toward / seg[:, None], _directions(n, rng))
    seg = np.where(state == SLOT_LIGHT, seg, np.inf)
    flags = rng.choice([NONE, TEST_ANALYTIC, TEST_ANALYTIC, TEST_ANALYTIC, VISIBLE], n).astype(np.int8)
    given = {"state": state, "light": light, "seg": seg, "wdir": wdir}
    scalar = _run("analytic_shadows", scene, m, point, normal, error, flags=flags, **given)
    lanes = _run("analytic_shadows_lanes", scene, m, point, normal, error, flags=flags, **given)
    np.testing.assert_array_equal(lanes.flags, scalar.flags)
    np.testing.assert_array_equal(lanes.flags[flags != TEST_ANALYTIC], flags[flags != TEST_ANALYTIC])
    for bounded in (True, False):
        tested = lanes.flags[(flags == TEST_ANALYTIC) & ((state == SLOT_LIGHT) == bounded)]
        assert not np.any(tested == TEST_ANALYTIC)
        assert np.count_nonzero(tested == BLOCKED) > 100  # the ground, the wall, the spheres block many
        assert np.count_nonzero(tested == VISIBLE) > 100
        assert np.count_nonzero(tested == TEST_MESH) > 20  # the blobs, or the light triangles (a mesh too)


def test_a_shape_hierarchy_is_walked_one_ray_at_a_time():
    """Above 16 shapes the scene has a shape hierarchy, which the lanes do not walk: its plan runs the scalar twins
    of both lane stages (``Plan.shape_tree``), and the scene with 16 shapes or fewer the lanes."""
    from lightprobe.integrators.wavefront import RenderSettings, plan_for

    scene = _scene()
    few = plan_for(scene, RenderSettings()).stages()
    assert scene.compile().tree_skip.shape[0] == 0
    for i in range(20):
        scene.add(Sphere([-3.0 + 0.3 * i, 0.1, 2.5], 0.1), "m")
    assert scene.compile().tree_skip.shape[0] > 0
    many = plan_for(scene, RenderSettings()).stages()
    for vector, scalar in (
        ("nearest_analytic_lanes", "nearest_analytic"),
        ("analytic_shadows_lanes", "analytic_shadows"),
    ):
        assert pipeline.STAGES[pipeline.stage_id(vector)].twin == scalar
        assert vector in few and scalar not in few, few
        assert scalar in many and vector not in many, many


# --- unbounded shadow rays (a scene lit by an environment map) ----------------------------------------------------


def _shadow_stage(name, arrays, m, point, normal, wdir, flags):
    """Run shadow stage ``name`` on shading points with their normals and the slots' directions; ``flags`` (in
    place) become the stage's answers."""
    c = records.constants(m)
    cams = records.cameras(point.shape[0], point=point, gnormal=normal, point_error=_errors(point, normal))
    slots = records.slots(wdir.shape[0], wdir=wdir, flags=flags)
    records.run(name, records.records(c, cams, slots, arrays=arrays))
    flags[:] = slots.flags


def _environment_scene(meshes=True, spheres=True):
    """The occluders under a uniform environment map, compiled."""
    sc = Scene(Camera([0, 1, 5], [0, 0, 0]), EnvironmentMap.from_array(np.ones((2, 4, 3))))
    return _occluders(sc, meshes, spheres).compile()


def _occluders(sc, meshes, spheres):
    """Two blobs, two spheres, the ground and a wall, added to scene ``sc``."""
    sc.add_material("m", Lambert(0.5))
    if meshes:
        sc.add(blob_mesh(2), "m", transform={"scale": 0.7, "translate": [0, 0.8, 0]})
        sc.add(blob_mesh(1), "m", transform={"scale": 0.3, "translate": [1.5, 0.3, 0.5]})
    if spheres:
        sc.add(Sphere([-1.5, 0.5, 0], 0.5), "m")
        sc.add(Sphere([0.5, 1.8, -1.0], 0.3), "m")
    sc.add(Rectangle.ground(size=8), "m")
    sc.add(Rectangle([-2.0, 0.0, -2.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.5]), "m")  # a wall facing +x
    return sc


def _unbounded_rays(n_samples, m, seed):
    """Shading points (``_points``) and for each of their m slots a random direction, every seventh along an axis,
    with a flag: most TEST_ANALYTIC, some not to be tested."""
    rng = np.random.default_rng(seed)
    point, normal, _ = _points(n_samples, seed)
    wdir = _directions(n_samples * m, rng)
    flags = rng.choice([NONE, TEST_ANALYTIC, TEST_ANALYTIC, TEST_ANALYTIC, VISIBLE], n_samples * m).astype(np.int8)
    return point, normal, wdir, flags


@pytest.mark.parametrize(("meshes", "spheres", "m"), [(True, True, 5), (True, True, 8), (False, False, 3)])
def test_unbounded_shadow_rays_are_flagged_as_the_scalar_stage_does(meshes, spheres, m):
    """Blocked, to be tested against the meshes, or visible: the same flag for every slot flagged TEST_ANALYTIC
    (a pass length that is not a multiple of 8, camera samples of m slots across blocks), every other slot
    untouched; scenes without meshes or spheres too (the lanes' loops run zero times)."""
    arrays = _environment_scene(meshes, spheres)
    point, normal, wdir, flags = _unbounded_rays(2503, m, seed=m)
    scalar, lanes = flags.copy(), flags.copy()
    _shadow_stage("analytic_shadows", arrays, m, point, normal, wdir, scalar)
    _shadow_stage("analytic_shadows_lanes", arrays, m, point, normal, wdir, lanes)
    assert np.array_equal(lanes, scalar)
    assert np.array_equal(lanes[flags != TEST_ANALYTIC], flags[flags != TEST_ANALYTIC])
    tested = lanes[flags == TEST_ANALYTIC]
    assert not np.any(tested == TEST_ANALYTIC)
    assert np.count_nonzero(tested == BLOCKED) > 300  # the ground, the wall and the spheres block many
    assert np.count_nonzero(tested == VISIBLE) > 300
    assert (np.count_nonzero(tested == TEST_MESH) > 50) == meshes


def test_the_mesh_spheres_only_settle_rays_the_boxes_sent_to_embree():
    """With each mesh's spheres (geometry/proxies.py) a ray the boxes alone would send to Embree may become BLOCKED
    (through a closed mesh's inner ball) or VISIBLE (past the sphere around it); no other ray's flag changes.
    Lanes and scalar stage both."""
    arrays = _environment_scene()
    boxes_only = arrays._replace(mesh_spheres=np.tile([0.0, 0.0, 0.0, 1e300, -1.0], (arrays.mesh_spheres.shape[0], 1)))
    point, normal, wdir, flags = _unbounded_rays(2503, 8, seed=5)
    for stage in ("analytic_shadows_lanes", "analytic_shadows"):
        with_spheres, without = flags.copy(), flags.copy()
        _shadow_stage(stage, arrays, 8, point, normal, wdir, with_spheres)
        _shadow_stage(stage, boxes_only, 8, point, normal, wdir, without)
        sent = without == TEST_MESH
        np.testing.assert_array_equal(with_spheres[~sent], without[~sent])
        assert np.count_nonzero(with_spheres[sent] == BLOCKED) > 100
        assert np.count_nonzero(with_spheres[sent] == VISIBLE) > 100
        assert np.count_nonzero(with_spheres[sent] == TEST_MESH) > 50


def test_a_ray_grazing_a_sphere_or_leaving_its_surface():
    """Rays tangent to a sphere and rays leaving its surface outward (the offset origin must not hit it) or
    inward (it must), one lane each, against the scalar stage."""
    arrays = _environment_scene(meshes=False)
    centre, radius = np.array([-1.5, 0.5, 0.0]), 0.5
    normals = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.6, 0.8, 0.0]])
    point = centre + radius * normals
    # per point: outward, inward, tangent, and tangent shifted a hair toward the centre
    wdir = []
    for n in normals:
        t = np.cross(n, [0.3, 0.2, 0.9])
        t /= np.linalg.norm(t)
        wdir += [n, -n, t, (t - 1e-9 * n) / np.linalg.norm(t - 1e-9 * n)]
    wdir = np.array(wdir)
    flags = np.full(wdir.shape[0], TEST_ANALYTIC, np.int8)
    scalar, lanes = flags.copy(), flags.copy()
    _shadow_stage("analytic_shadows", arrays, 4, point, normals, wdir, scalar)
    _shadow_stage("analytic_shadows_lanes", arrays, 4, point, normals, wdir, lanes)
    assert np.array_equal(lanes, scalar)
    assert np.all(lanes[0::4] == VISIBLE)  # nothing else in their way
    assert np.all(lanes[1::4] == BLOCKED)


def test_rays_from_inside_a_sphere_square_to_its_centre():
    """A ray that starts inside a sphere (another object's point there) square to the direction of the centre:
    its nearest point to the centre is its origin (bq = 0 exactly), and it leaves the sphere, so it is blocked; the
    lanes and the scalar stage must both see it leave."""
    arrays = _environment_scene(meshes=False)
    centre, radius = np.array([-1.5, 0.5, 0.0]), 0.5
    offsets = np.array([[0.3, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, -0.4], [0.1, 0.0, 0.0]]) * radius / 0.5
    point = centre + offsets
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    wdir = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    flags = np.full(4, TEST_ANALYTIC, np.int8)
    scalar, lanes = flags.copy(), flags.copy()
    _shadow_stage("analytic_shadows", arrays, 1, point, normals, wdir, scalar)
    _shadow_stage("analytic_shadows_lanes", arrays, 1, point, normals, wdir, lanes)
    assert np.array_equal(lanes, scalar)
    assert np.all(lanes == BLOCKED)
