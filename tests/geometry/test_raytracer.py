"""Ray queries: Embree + analytic shapes against brute force, occlusion against closest hit, the camera."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.demo import blob_mesh
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.intersect import MESH, MISS, RECT, SPHERE
from lightprobe.geometry.raytracer import RayTracer
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.scene import Scene


@pytest.fixture(scope="module")
def scene():
    sc = Scene(Camera([0, 1, 5], [0, 0, 0]), EnvironmentMap.from_array(np.ones((2, 4, 3))))
    sc.add_material("m", Lambert(0.5))
    sc.add(blob_mesh(3), "m", transform={"scale": 0.7, "translate": [0, 0.8, 0]})
    sc.add(blob_mesh(2), "m", transform={"scale": 0.3, "rotate": [1, 0, 0, 40], "translate": [1.5, 0.3, 0]})
    sc.add(Sphere([-1.5, 0.5, 0], 0.5), "m")
    sc.add(Rectangle.ground(size=8), "m")
    return sc


def random_rays(n, seed=0):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-3, 3, (n, 3))
    o[:, 1] = rng.uniform(0.01, 3, n)
    d = rng.normal(size=(n, 3))
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


def brute_force(arrays, o, d):
    """Nearest hit by Moeller-Trumbore over every triangle, plus the analytic shapes solved directly."""
    v = arrays.mesh_vertices
    f = arrays.mesh_faces
    v0, e1, e2 = v[f[:, 0]], v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    p = np.cross(d, e2)
    det = e1 @ np.zeros(3) + np.einsum("ij,ij->i", e1, p)
    s = o - v0
    u = np.einsum("ij,ij->i", s, p) / det
    q = np.cross(s, e1)
    w = (q @ d) / det
    t = np.einsum("ij,ij->i", e2, q) / det
    t = np.where((u >= 0) & (w >= 0) & (u + w <= 1) & (t > 1e-9), t, np.inf)
    best, kind, face = t.min(), MESH, int(t.argmin())
    for c in arrays.spheres:
        oc = o - c[:3]
        b = oc @ d
        disc = b * b - (oc @ oc - c[3] ** 2)
        if disc >= 0:
            for root in (-b - np.sqrt(disc), -b + np.sqrt(disc)):
                if 1e-9 < root < best:
                    best, kind = root, SPHERE
                    break
    for r in arrays.rects:
        n = r[9:12]
        tt = (r[:3] - o) @ n / (d @ n)
        if 1e-9 < tt < best:
            x = o + tt * d - r[:3]
            a, b = x @ r[3:6] / (r[3:6] @ r[3:6]), x @ r[6:9] / (r[6:9] @ r[6:9])
            if 0 <= a <= 1 and 0 <= b <= 1:
                best, kind = tt, RECT
    return (best, kind if np.isfinite(best) else MISS, face)


def test_intersect_agrees_with_brute_force(scene):
    arrays = scene.compile()
    tracer = RayTracer(arrays)
    o, d = random_rays(3000)
    t, kind, index, prim, _, _ = tracer.intersect(o, d)
    mismatches = 0
    for i in range(len(o)):
        tb, kb, fb = brute_force(arrays, o[i], d[i])
        if kb != kind[i] or (np.isfinite(tb) and abs(tb - t[i]) > 1e-4 * max(1.0, tb)):
            mismatches += 1
        elif kb == MESH and arrays.mesh_face_start[index[i]] + prim[i] != fb:
            mismatches += 1
    # Embree works in float32: allow ties at shared edges, nothing more
    assert mismatches <= 2, mismatches
    assert set(np.unique(kind)) == {MISS, MESH, SPHERE, RECT}


def test_barycentrics_rebuild_the_hit_point(scene):
    arrays = scene.compile()
    o, d = random_rays(20000, seed=1)
    t, kind, index, prim, b1, b2 = RayTracer(arrays).intersect(o, d)
    hit = np.nonzero(kind == MESH)[0]
    f = arrays.mesh_faces[arrays.mesh_face_start[index[hit]] + prim[hit]]
    v = arrays.mesh_vertices
    p = (1 - b1[hit, None] - b2[hit, None]) * v[f[:, 0]] + b1[hit, None] * v[f[:, 1]] + b2[hit, None] * v[f[:, 2]]
    np.testing.assert_allclose(p, o[hit] + t[hit, None] * d[hit], atol=1e-5)


def test_occlusion_agrees_with_closest_hit(scene):
    tracer = RayTracer(scene.compile())
    o, d = random_rays(100_000, seed=2)
    t, kind, *_ = tracer.intersect(o, d)
    np.testing.assert_array_equal(tracer.occluded(o, d), kind != MISS)
    # a segment shorter than the hit distance is not blocked
    short = np.where(np.isfinite(t), 0.5 * t, 1.0)
    assert not tracer.occluded(o, d, short).any()
    assert np.array_equal(tracer.occluded(o, d, np.where(np.isfinite(t), 1.001 * t, 1.0)), kind != MISS)


def test_threads_give_identical_hits(scene):
    import numba

    arrays = scene.compile()
    o, d = random_rays(100_000, seed=3)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = RayTracer(arrays).intersect(o, d)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = RayTracer(arrays).intersect(o, d)
    finally:
        numba.set_num_threads(before)
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a, b)


def test_camera_matches_the_peer_description():
    spec = Path(__file__).resolve().parents[3] / "shared" / "peers" / "scene.json"
    if not spec.exists():
        pytest.skip("../shared/peers/scene.json is absent")
    cam = json.loads(spec.read_text())["camera"]
    camera = Camera(
        cam["origin"],
        cam["target"],
        cam["up"],
        fov=cam["fov_deg"],
        fov_axis=cam["fov_axis"],
        resolution=cam["resolution"],
    )
    _, corner = camera.rays([0], [[0.0, 0.0]])
    np.testing.assert_allclose(corner[0], cam["check"]["direction_through_top_left_image_corner"], atol=1e-6)
    w, h = cam["resolution"]
    _, centre = camera.rays([(h // 2) * w + w // 2], [[0.0, 0.0]])
    np.testing.assert_allclose(centre[0], cam["check"]["direction_through_image_centre"], atol=1e-6)


def test_camera_orientation_and_fov():
    camera = Camera([0, 0, 0], [0, 0, -1], fov=90.0, resolution=(4, 2))
    _, d = camera.rays([0, 3, 4], [[0, 0], [1, 0], [0, 1]])
    # top-left corner: left (-X) and up (+Y); vertical fov 90 -> tan = 1 vertically, 2 horizontally
    np.testing.assert_allclose(d[0], np.array([-2, 1, -1]) / np.sqrt(6), atol=1e-12)
    np.testing.assert_allclose(d[1], np.array([2, 1, -1]) / np.sqrt(6), atol=1e-12)
    np.testing.assert_allclose(d[2], np.array([-2, -1, -1]) / np.sqrt(6), atol=1e-12)


def test_a_closed_tracer_refuses_rather_than_missing_the_meshes(scene):
    from lightprobe.errors import LightprobeError
    from lightprobe.integrators.wavefront import RenderSettings, render

    tracer = RayTracer(scene.compile())
    tracer.close()
    o, d = random_rays(10, seed=4)
    with pytest.raises(LightprobeError, match="closed"):
        tracer.intersect(o, d)
    with pytest.raises(LightprobeError, match="closed"):
        render(scene, RenderSettings(spp=1), tracer=tracer)
