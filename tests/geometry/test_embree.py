"""Embree's C API called from Numba kernels: hits, barycentrics, segment ends and ids against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.geometry.embree import (
    FAR,
    EmbreeScene,
    intersect_batch,
    new_scratch,
    occluded_batch,
    occluded_packets_batch,
    packets_native,
)

# two meshes: a unit right triangle in the plane z = 1 (mesh 0, faces 0-1: a square split in two) and a
# triangle in z = 3 (mesh 1)
VERTICES = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1], [-5, -5, 3], [5, -5, 3], [0, 5, 3]], dtype=np.float64)
FACES = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]])
FACE_START = np.array([0, 2, 3])


@pytest.fixture(scope="module")
def scene():
    sc = EmbreeScene(VERTICES, FACES, FACE_START)
    yield sc
    sc.close()


def rays_up(xy):
    """Rays from z = 0 straight up through the points xy."""
    n = xy.shape[0]
    origins = np.column_stack([xy, np.zeros(n)])
    dirs = np.tile([0.0, 0.0, 1.0], (n, 1))
    return origins, dirs


def test_closest_hits_match_the_closed_form(scene):
    rng = np.random.default_rng(0)
    xy = rng.uniform(0.02, 0.98, (20_000, 2))
    xy = xy[np.abs(xy[:, 0] - xy[:, 1]) > 1e-3]  # away from the shared diagonal
    o, d = rays_up(xy)
    t, mesh, face, b1, b2 = intersect_batch(scene.handle, new_scratch(), o, d, np.full(len(o), FAR, np.float32))
    np.testing.assert_array_equal(mesh, 0)
    lower = xy[:, 0] > xy[:, 1]  # below the diagonal: face 0 = (v0, v1, v2)
    np.testing.assert_array_equal(face, np.where(lower, 0, 1))
    np.testing.assert_allclose(t, 1.0, atol=1e-6)
    # p = (1 - b1 - b2) v0 + b1 v1 + b2 v2: face 0 has b1 = x - y, b2 = y; face 1 (v0, v2, v3) has b1 = x, b2 = y - x
    np.testing.assert_allclose(b1, np.where(lower, xy[:, 0] - xy[:, 1], xy[:, 0]), atol=2e-6)
    np.testing.assert_allclose(b2, np.where(lower, xy[:, 1], xy[:, 1] - xy[:, 0]), atol=2e-6)


def test_second_mesh_ids_and_misses(scene):
    o, d = rays_up(np.array([[2.0, 0.0], [0.5, 0.25], [50.0, 0.0]]))
    t, mesh, face, _, _ = intersect_batch(scene.handle, new_scratch(), o, d, np.full(3, FAR, np.float32))
    assert mesh.tolist() == [1, 0, -1]
    assert face.tolist() == [0, 0, -1]  # face numbers count within each mesh
    np.testing.assert_allclose(t[:2], [3.0, 1.0], atol=1e-6)


def test_segment_ends_are_respected(scene):
    o, d = rays_up(np.array([[0.5, 0.25], [2.0, 0.0]]))
    scratch = new_scratch()
    assert occluded_batch(scene.handle, scratch, o, d, np.full(2, FAR, np.float32)).tolist() == [True, True]
    # segments ending before the triangles are not blocked; the closest hit then reports nothing
    short = np.array([0.99, 2.99], np.float32)
    assert occluded_batch(scene.handle, scratch, o, d, short).tolist() == [False, False]
    _, mesh, *_ = intersect_batch(scene.handle, scratch, o, d, short)
    assert mesh.tolist() == [-1, -1]
    # pointing away: nothing
    assert not occluded_batch(scene.handle, scratch, o, -d, np.full(2, FAR, np.float32)).any()


needs_packets = pytest.mark.skipif(not packets_native(), reason="no native 8-ray packets on this CPU")


@needs_packets
def test_packets_answer_as_single_rays(scene):
    """Shadow rays 8 per rtcOccluded8 call (the render's mesh shadow stage) block where rtcOccluded1 does, ray for
    ray: random origins and directions, segments that end before, on and past the triangles, a partial last
    packet (20 003 rays)."""
    rng = np.random.default_rng(3)
    n = 20_003
    o = np.column_stack([rng.uniform(-1, 2, n), rng.uniform(-1, 2, n), rng.uniform(-1, 4, n)])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    far = np.where(rng.uniform(size=n) < 0.5, FAR, rng.uniform(0, 4, n)).astype(np.float32)
    scratch = new_scratch()
    single = occluded_batch(scene.handle, scratch, o, d, far)
    packets = occluded_packets_batch(scene.handle, scratch, o, d, far)
    assert 0.05 < single.mean() < 0.95  # both answers are common
    np.testing.assert_array_equal(packets, single)


@needs_packets
def test_packets_of_every_fill_answer_their_own_rays(scene):
    """Lanes past a partial packet's end are not traced and change nothing: 1 to 9 rays, alternately blocked."""
    o, d = rays_up(np.array([[0.5, 0.25], [50.0, 0.0]] * 5)[:9])
    for count in range(1, 10):
        blocked = occluded_packets_batch(
            scene.handle, new_scratch(), o[:count], d[:count], np.full(count, FAR, np.float32)
        )
        assert blocked.tolist() == [i % 2 == 0 for i in range(count)]


def test_close_is_idempotent():
    sc = EmbreeScene(VERTICES, FACES, FACE_START)
    assert sc.handle != 0
    sc.close()
    sc.close()
    assert sc.handle == 0
