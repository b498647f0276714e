"""The analytic shadow tests in lanes (integrators/stages/shadow_lanes.py) against the scalar stage, ray for ray."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.demo import blob_mesh
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.intersect import ANALYTIC_ERROR
from lightprobe.geometry.scene import Scene
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.integrators.techniques import BLOCKED, NONE, TEST_ANALYTIC, TEST_MESH, VISIBLE

from . import records

LANES_STAGE, SCALAR_STAGE = "analytic_shadows_lanes", "analytic_shadows"


def _shadow_stage(name, arrays, m, point, normal, wdir, flags):
    """Run shadow stage ``name`` on shading points with their normals and the slots' directions; ``flags`` (in
    place) become the stage's answers."""
    c = records.constants(m)
    cams = records.cameras(point.shape[0], point=point, gnormal=normal, point_error=_errors(point, normal))
    slots = records.slots(wdir.shape[0], wdir=wdir, flags=flags)
    records.run(name, records.records(c, cams, slots, arrays=arrays))
    flags[:] = slots.flags


def _scene(meshes=True, spheres=True):
    sc = Scene(Camera([0, 1, 5], [0, 0, 0]), EnvironmentMap.from_array(np.ones((2, 4, 3))))
    sc.add_material("m", Lambert(0.5))
    if meshes:
        sc.add(blob_mesh(2), "m", transform={"scale": 0.7, "translate": [0, 0.8, 0]})
        sc.add(blob_mesh(1), "m", transform={"scale": 0.3, "translate": [1.5, 0.3, 0.5]})
    if spheres:
        sc.add(Sphere([-1.5, 0.5, 0], 0.5), "m")
        sc.add(Sphere([0.5, 1.8, -1.0], 0.3), "m")
    sc.add(Rectangle.ground(size=8), "m")
    sc.add(Rectangle([-2.0, 0.0, -2.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.5]), "m")  # a wall facing +x
    return sc.compile()


def _errors(point, normal):
    """Error bounds of analytic points (intersect.point_error with a shape of size 8, the ground's)."""
    return ANALYTIC_ERROR * (np.abs(point) * np.abs(normal)).sum(axis=1) + ANALYTIC_ERROR * 8.0


def _rays(n_samples, m, seed):
    """Shading points on and above the ground, half of them on the sphere; directions random, axis-aligned (the
    slab test's zero components) and grazing the sphere."""
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
    wdir = rng.normal(size=(n_samples * m, 3))
    wdir[::7] = np.eye(3)[rng.integers(0, 3, wdir[::7].shape[0])] * rng.choice([-1.0, 1.0], (wdir[::7].shape[0], 1))
    wdir /= np.linalg.norm(wdir, axis=1)[:, None]
    flags = rng.choice([NONE, TEST_ANALYTIC, TEST_ANALYTIC, TEST_ANALYTIC, VISIBLE], n_samples * m).astype(np.int8)
    return point, normal, wdir, flags


@pytest.mark.parametrize(("meshes", "spheres", "m"), [(True, True, 5), (True, True, 8), (False, False, 3)])
def test_lanes_flag_every_ray_as_the_scalar_stage_does(meshes, spheres, m):
    """Blocked, to be tested against the meshes, or visible: the same flag for every slot flagged TEST_ANALYTIC
    (a pass length that is not a multiple of 8, camera samples of m slots across blocks), every other slot
    untouched; scenes without meshes or spheres too (the lanes' loops run zero times)."""
    arrays = _scene(meshes, spheres)
    point, normal, wdir, flags = _rays(2503, m, seed=m)
    scalar, lanes = flags.copy(), flags.copy()
    _shadow_stage(SCALAR_STAGE, arrays, m, point, normal, wdir, scalar)
    _shadow_stage(LANES_STAGE, arrays, m, point, normal, wdir, lanes)
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
    arrays = _scene()
    boxes_only = arrays._replace(mesh_spheres=np.tile([0.0, 0.0, 0.0, 1e300, -1.0], (arrays.mesh_spheres.shape[0], 1)))
    point, normal, wdir, flags = _rays(2503, 8, seed=5)
    for stage in (LANES_STAGE, SCALAR_STAGE):
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
    arrays = _scene(meshes=False)
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
    _shadow_stage(SCALAR_STAGE, arrays, 4, point, normals, wdir, scalar)
    _shadow_stage(LANES_STAGE, arrays, 4, point, normals, wdir, lanes)
    assert np.array_equal(lanes, scalar)
    assert np.all(lanes[0::4] == VISIBLE)  # nothing else in their way
    assert np.all(lanes[1::4] == BLOCKED)


def test_rays_from_inside_a_sphere_square_to_its_centre():
    """A ray that starts inside a sphere (another object's point there) square to the direction of the centre:
    its nearest point to the centre is its origin (bq = 0 exactly), and it leaves the sphere, so it is blocked; the
    lanes decide this without the root (geometry/shadow_lanes._sphere_blocks), the scalar stage from it."""
    arrays = _scene(meshes=False)
    centre, radius = np.array([-1.5, 0.5, 0.0]), 0.5
    offsets = np.array([[0.3, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, -0.4], [0.1, 0.0, 0.0]]) * radius / 0.5
    point = centre + offsets
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    wdir = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    flags = np.full(4, TEST_ANALYTIC, np.int8)
    scalar, lanes = flags.copy(), flags.copy()
    _shadow_stage(SCALAR_STAGE, arrays, 1, point, normals, wdir, scalar)
    _shadow_stage(LANES_STAGE, arrays, 1, point, normals, wdir, lanes)
    assert np.array_equal(lanes, scalar)
    assert np.all(lanes == BLOCKED)
