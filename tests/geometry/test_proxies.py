"""The spheres that decide shadow rays without Embree (geometry/proxies.py): closedness, winding numbers,
point-triangle distances, the spheres themselves, and Embree's agreement with them ray for ray."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert, RoughPlastic
from lightprobe.demo import blob_mesh
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.embree import FAR, EmbreeScene, new_scratch, occluded_batch
from lightprobe.geometry.mesh import TriangleMesh
from lightprobe.geometry.proxies import NO_BALL, closest_distances, is_closed, mesh_spheres, winding_number
from lightprobe.geometry.shapes import Rectangle
from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.scene import Scene

CUBE_VERTICES = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.float64
)
# outward winding (counter-clockwise seen from outside)
CUBE_FACES = np.array(
    [
        [0, 2, 1], [0, 3, 2],  # z = 0
        [4, 5, 6], [4, 6, 7],  # z = 1
        [0, 1, 5], [0, 5, 4],  # y = 0
        [3, 7, 6], [3, 6, 2],  # y = 1
        [0, 4, 7], [0, 7, 3],  # x = 0
        [1, 2, 6], [1, 6, 5],  # x = 1
    ]
)  # fmt: skip


def test_a_cube_is_closed_and_a_cube_with_a_hole_or_a_flipped_face_is_not():
    assert is_closed(CUBE_FACES)
    assert not is_closed(CUBE_FACES[1:])  # a missing triangle leaves a boundary
    flipped = CUBE_FACES.copy()
    flipped[3] = flipped[3, ::-1]  # one face against its neighbours' orientation
    assert not is_closed(flipped)
    assert is_closed(CUBE_FACES[:, ::-1])  # all reversed: still closed (inside out)
    assert not is_closed(np.zeros((0, 3), np.int64))


def test_winding_numbers_of_a_cube():
    assert winding_number(CUBE_VERTICES, CUBE_FACES, [0.5, 0.5, 0.5]) == pytest.approx(1.0, abs=1e-12)
    assert winding_number(CUBE_VERTICES, CUBE_FACES, [0.1, 0.9, 0.2]) == pytest.approx(1.0, abs=1e-12)
    assert winding_number(CUBE_VERTICES, CUBE_FACES, [1.5, 0.5, 0.5]) == pytest.approx(0.0, abs=1e-12)
    assert winding_number(CUBE_VERTICES, CUBE_FACES[:, ::-1], [0.5, 0.5, 0.5]) == pytest.approx(-1.0, abs=1e-12)
    # an open box (no top) is not an integer at its centre
    assert abs(winding_number(CUBE_VERTICES, CUBE_FACES[:10], [0.5, 0.5, 0.5]) - 1.0) > 0.1


def test_closest_distances_against_dense_samples_of_each_triangle():
    """Every region (vertex, edge, face) of random triangles: the distance is at most that of the nearest of 20 301
    points spread over the triangle, and within the samples' spacing of it."""
    rng = np.random.default_rng(7)
    vertices = rng.normal(size=(90, 3)) * 0.3
    faces = np.array([rng.choice(90, 3, replace=False) for _ in range(30)])
    n = 200
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    keep = i + j <= n
    u, v = i[keep] / n, j[keep] / n
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    points = a[:, None] + (b - a)[:, None] * u[None, :, None] + (c - a)[:, None] * v[None, :, None]
    spacing = np.max(np.linalg.norm(np.stack([b - a, c - a, c - b]), axis=2), axis=0) / n
    for point in rng.normal(size=(12, 3)):
        d = closest_distances(vertices, faces, point)
        sampled = np.linalg.norm(points - point, axis=2).min(axis=1)
        assert np.all(d <= sampled + 1e-12)
        assert np.all(d >= sampled - spacing)
    # a point on a face, on an edge and at a vertex
    cube = closest_distances(CUBE_VERTICES, CUBE_FACES, [0.5, 0.5, 0.5])
    np.testing.assert_allclose(cube, 0.5, atol=1e-15)
    outside = closest_distances(CUBE_VERTICES, CUBE_FACES, [2.0, 2.0, 2.0])
    assert outside.min() == pytest.approx(np.sqrt(3.0), abs=1e-15)
    # a face without area is its longest edge: the segment from (0, 0, 0) to (2, 0, 0), seen from above its middle
    # and from beyond its end
    line = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    degenerate = np.array([[0, 1, 2], [0, 2, 2]])
    np.testing.assert_allclose(closest_distances(line, degenerate, [1.5, 0.5, 0.0]), 0.5, atol=1e-15)
    np.testing.assert_allclose(closest_distances(line, degenerate, [3.0, 0.0, 1.0]), np.sqrt(2.0), atol=1e-15)


def test_the_spheres_of_a_closed_blob_and_of_an_open_one():
    mesh = blob_mesh(3)
    cx, cy, cz, outer2, inner2 = mesh_spheres(mesh.vertices, mesh.faces)
    centre = np.array([cx, cy, cz])
    reach = np.linalg.norm(mesh.vertices - centre, axis=1)
    assert np.all(reach < np.sqrt(outer2)) and np.sqrt(outer2) < reach.max() * 1.001
    nearest = closest_distances(mesh.vertices, mesh.faces, centre).min()
    assert 0.5 * nearest < np.sqrt(inner2) < nearest
    # without one triangle the surface has a hole: no inner ball, the outer sphere as before
    open_spheres = mesh_spheres(mesh.vertices, mesh.faces[1:])
    assert open_spheres[4] == NO_BALL
    assert open_spheres[3] >= reach.max() ** 2
    # a closed surface whose centre is outside it (two cubes apart): no ball there
    apart = mesh_spheres(
        np.vstack([CUBE_VERTICES, CUBE_VERTICES + np.array([3.0, 0.0, 0.0])]), np.vstack([CUBE_FACES, CUBE_FACES + 8])
    )
    assert apart[4] == NO_BALL


def test_embree_blocks_every_ray_through_the_inner_ball_and_no_ray_outside_the_outer_one():
    """The spheres' answers are Embree's own: 40 000 rays from around a closed blob, aimed near its centre."""
    mesh = blob_mesh(3)
    cx, cy, cz, outer2, inner2 = mesh_spheres(mesh.vertices, mesh.faces)
    centre = np.array([cx, cy, cz])
    rng = np.random.default_rng(11)
    n = 40_000
    start = rng.normal(size=(n, 3))
    start = centre + start / np.linalg.norm(start, axis=1, keepdims=True) * rng.uniform(1.2, 3.0, (n, 1))
    aim = centre + rng.normal(size=(n, 3)) * 0.7
    d = aim - start
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    f = start - centre
    along = -np.einsum("ij,ij->i", f, d)
    miss2 = np.einsum("ij,ij->i", f + along[:, None] * d, f + along[:, None] * d)
    through_ball = (miss2 < inner2) & (along > 0)
    outside = miss2 > outer2
    scene = EmbreeScene(mesh.vertices, mesh.faces, np.array([0, mesh.faces.shape[0]]))
    try:
        blocked = occluded_batch(scene.handle, new_scratch(), start, d, np.full(n, FAR, np.float32))
    finally:
        scene.close()
    assert through_ball.sum() > 5000 and outside.sum() > 5000
    assert np.all(blocked[through_ball])
    assert not np.any(blocked[outside])


def test_a_render_is_the_same_bits_without_the_spheres(monkeypatch):
    """The spheres change who answers a shadow ray, not the answer: a closed blob (inner ball and outer sphere) and
    an open one (outer sphere only) over a ground, under a map with a sun, give the same image bits with every
    mesh's spheres replaced by ones that decide nothing -- and with them Embree traces fewer rays."""
    rng = np.random.default_rng(2)
    sky = 0.3 + rng.uniform(size=(16, 32, 3))
    sky[4, 9] = 400.0  # a sun, for sharp shadows of the blobs on the ground
    scene = Scene(Camera([0, 1.5, 5], [0, 0.5, 0], resolution=(48, 36)), EnvironmentMap.from_array(sky))
    scene.add(blob_mesh(2), Lambert(0.6), transform={"scale": 0.7, "translate": [-0.6, 0.8, 0]})
    hole = blob_mesh(2)
    scene.add(
        TriangleMesh(hole.vertices, hole.faces[2:], hole.normals),
        RoughPlastic([0.2, 0.3, 0.6], 0.2),
        transform={"scale": 0.5, "translate": [0.9, 0.6, 0.4]},
    )
    scene.add(Rectangle.ground(size=8), Lambert(0.5))
    spheres = scene.compile().mesh_spheres
    assert spheres[0, 4] > 0.0 and spheres[1, 4] == NO_BALL
    settings = RenderSettings(spp=8)
    with_spheres = render(scene, settings)
    monkeypatch.setattr(TriangleMesh, "spheres", property(lambda mesh: np.array([0.0, 0.0, 0.0, 1e300, NO_BALL])))
    assert scene.compile().mesh_spheres[0, 3] == 1e300
    without = render(scene, settings)
    assert np.array_equal(with_spheres.image, without.image)
    assert np.array_equal(with_spheres.variance, without.variance)
    assert with_spheres.stats["embree_rays"] < 0.8 * without.stats["embree_rays"]
