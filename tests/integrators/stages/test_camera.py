"""The camera stage's nearest hits, the shape tests in lanes (integrators/stages/ray_lanes.py), against the scalar
stage, ray for ray."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.demo import blob_mesh
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.geometry import embree
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.embree import new_scratch
from lightprobe.geometry.intersect import MESH, MISS, RECT, SPHERE
from lightprobe.geometry.raytracer import RayTracer
from lightprobe.geometry.shape_bvh import SHAPES_FOR_BVH
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.integrators import wavefront
from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.sampling.rng import SAMPLERS
from lightprobe.scene import Scene

from . import records


def _scene(meshes=True, spheres=True, resolution=(97, 89)):
    sc = Scene(Camera([0, 1, 5], [0, 0.5, 0], resolution=resolution), EnvironmentMap.from_array(np.ones((2, 4, 3))))
    sc.add_material("m", Lambert(0.5))
    if meshes:
        sc.add(blob_mesh(2), "m", transform={"scale": 0.7, "translate": [0, 0.8, 0]})
    if spheres:
        sc.add(Sphere([-1.5, 0.5, 0], 0.5), "m")
        sc.add(Sphere([-1.2, 0.7, 0.3], 0.4), "m")  # overlaps the first: the nearer of two hits must win
        sc.add(Sphere([1.2, 0.6, 1.0], 0.6), "m")
    sc.add(Rectangle.ground(size=6), "m")
    sc.add(Rectangle([-2.0, 0.0, -2.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.5]), "m")  # a wall facing +x
    sc.add(Rectangle([-1.0, 0.0, -2.5], [2.0, 0.0, 0.0], [0.0, 1.5, 0.0]), "m")  # a back wall behind the mesh
    return sc


def _hits(stage, scene, cam, spp_pass=3, tracer=None, sampler="sobol"):
    """(t, kind, index, prim) of every camera sample of one pass over all pixels, ``spp_pass`` samples each."""
    arrays = scene.compile()
    width, height = scene.camera.resolution
    pixels = np.arange(width * height, dtype=np.int64)
    n = pixels.size * spp_pass  # 25 899 for 97 x 89 x 3: not a multiple of 8
    c = records.constants(
        2, sampler=SAMPLERS[sampler], seed=7, pixels=pixels, spp_pass=spp_pass, cam=cam,
        mesh_scene=tracer.mesh_scene if tracer is not None else 0,
        scratch=tracer.scratch if tracer is not None else new_scratch(),
    )  # fmt: skip
    cams = records.cameras(n)
    records.run(stage, records.records(c, cams, records.slots(2 * n), arrays=arrays))
    return cams._asdict()


@pytest.mark.parametrize(
    ("meshes", "spheres", "inside", "sampler"),
    [
        (False, True, False, "sobol"),
        (False, False, False, "sobol"),
        (False, True, True, "sobol"),
        (False, True, False, "independent"),
    ],
)
def test_lanes_find_every_nearest_hit_the_scalar_pass_finds(meshes, spheres, inside, sampler):
    """The same directions, distances, kinds and indices for every camera ray (a pass that is not a multiple of 8;
    overlapping spheres; rectangles behind spheres; a scene without spheres, where the lanes' sphere loop runs zero
    times), from an origin inside a sphere, where the far root is the hit, and with either sampler (the Sobol'
    numbers come from lanes too)."""
    scene = _scene(meshes, spheres)
    cam = scene.camera.kernel_array()
    if inside:
        cam[0:3] = [-1.5, 0.6, 0.1]  # inside both overlapping spheres
    scalar = _hits("camera_scalar", scene, cam, sampler=sampler)
    lanes = _hits("camera", scene, cam, sampler=sampler)
    for name in ("dirs", "t", "kind", "index"):
        assert np.array_equal(lanes[name], scalar[name]), name
    kinds = lanes["kind"]
    assert np.all(np.isinf(lanes["t"][kinds == MISS])) and np.all(lanes["index"][kinds == MISS] == -1)
    if inside:
        assert np.all(kinds == SPHERE) and np.all(lanes["t"] < 0.8)  # each ray's way out, within a diameter
        return
    assert np.count_nonzero(kinds == RECT) > 2000 and np.count_nonzero(kinds == MISS) > 1000
    if spheres:
        assert np.count_nonzero(kinds == SPHERE) > 2000 and set(lanes["index"][kinds == SPHERE].tolist()) == {0, 1, 2}


@pytest.mark.parametrize("sampler", ["sobol", "independent"])
def test_the_tree_stage_finds_every_nearest_hit_the_scalar_pass_finds(sampler):
    """A scene of more than SHAPES_FOR_BVH spheres and rectangles runs ``camera_tree`` (its rays walk the shapes'
    hierarchy): the same directions and hits as the scalar stage, ray for ray, and the plan picks it."""
    scene = _scene(resolution=(61, 47))
    for i in range(SHAPES_FOR_BVH):
        scene.add(Sphere([-2.0 + 0.25 * i, 0.15 + 0.05 * (i % 3), 1.6], 0.12), "m")
    assert scene.compile().tree_skip.shape[0] > 0
    cam = scene.camera.kernel_array()
    scalar = _hits("camera_scalar", scene, cam, sampler=sampler)
    tree = _hits("camera_tree", scene, cam, sampler=sampler)
    for name in ("dirs", "t", "kind", "index"):
        assert np.array_equal(tree[name], scalar[name]), name
    assert np.count_nonzero(tree["kind"] == SPHERE) > 500 and len(set(tree["index"][tree["kind"] == SPHERE])) > 10
    plan = wavefront.plan_for(scene, RenderSettings(spp=1))
    assert plan.shape_tree and plan.stages()[0] == ("camera_tree" if plan.lanes else "camera_scalar")


def test_lanes_and_the_scalar_pass_leave_the_same_mesh_hits():
    """With a mesh, the lanes' analytic hits bound Embree's search as the scalar pass's do: same hits, same
    faces and barycentrics."""
    scene = _scene(meshes=True)
    tracer = RayTracer(scene.compile())
    try:
        cam = scene.camera.kernel_array()
        scalar = _hits("camera_scalar", scene, cam, tracer=tracer)
        lanes = _hits("camera", scene, cam, tracer=tracer)
    finally:
        tracer.close()
    for name in ("t", "kind", "index", "prim", "b1", "b2"):
        assert np.array_equal(lanes[name], scalar[name]), name
    assert np.count_nonzero(lanes["kind"] == MESH) > 1000


def test_a_render_is_the_same_with_the_scalar_camera_pass(monkeypatch):
    """The render picks the lanes where they compile; the scalar pass (the fallback) gives the same image bits."""
    scene = _scene(resolution=(40, 30))
    settings = RenderSettings(spp=4)
    lanes = render(scene, settings)
    assert "camera" in lanes.stats["stages"]
    plan_for = wavefront.plan_for
    monkeypatch.setattr(wavefront, "plan_for", lambda scene, settings: replace(plan_for(scene, settings), lanes=False))
    scalar = render(scene, settings)
    assert "camera_scalar" in scalar.stats["stages"]
    assert np.array_equal(lanes.image, scalar.image) and np.array_equal(lanes.variance, scalar.variance)


def test_a_render_is_the_same_with_single_mesh_shadow_rays(monkeypatch):
    """The mesh shadow rays go 8 per Embree call where packets are native; one per call (the fallback) gives the
    same image bits."""
    if not embree.packets_native():
        pytest.skip("no native 8-ray packets on this CPU")
    scene = _scene(resolution=(40, 30))
    settings = RenderSettings(spp=4)
    packets = render(scene, settings)
    plan_for = wavefront.plan_for
    monkeypatch.setattr(
        wavefront, "plan_for", lambda scene, settings: replace(plan_for(scene, settings), packets=False)
    )
    single = render(scene, settings)
    assert "mesh_shadows" in packets.stats["stages"] and "mesh_shadows_single" in single.stats["stages"]
    assert packets.stats["embree_rays"] == single.stats["embree_rays"] > 0
    assert np.array_equal(packets.image, single.image) and np.array_equal(packets.variance, single.variance)
