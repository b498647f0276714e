"""Ray queries: analytic shapes in Numba, triangle meshes in Embree 4 (``embreex``), batches split over threads.

One ``embreex`` call runs on one thread but releases the GIL, so a batch is cut into ``threads`` chunks run from
a thread pool (measured on this machine: 1.95x with 2 threads).  Pitfalls handled here: embreex takes float32
C-contiguous arrays only and has no per-ray tnear (callers offset origins, see
:func:`lightprobe.geometry.intersect.ray_offset`); ``OCCLUDED`` returns -1 for unblocked rays; the BVH is built on
the first query, which :class:`RayTracer` triggers at construction so that timings exclude it.

Closest-hit queries take a per-ray ``tfar`` (the nearest analytic hit), so Embree only reports closer triangles.
"""

from __future__ import annotations

import itertools
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .._numba import jit_parallel, prange
from .intersect import MESH, MISS, closest_analytic, may_hit_mesh, occluded_analytic
from .scene import SceneArrays

__all__ = ["RayTracer"]

MIN_CHUNK = 16_384  # below this, splitting a batch over threads costs more than it gains


@jit_parallel
def _closest_analytic_batch(s, o, d):
    n = d.shape[0]
    t = np.empty(n)
    kind = np.empty(n, dtype=np.int64)
    index = np.empty(n, dtype=np.int64)
    needs_mesh = np.empty(n, dtype=np.bool_)
    for i in prange(n):
        t[i], kind[i], index[i] = closest_analytic(s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], np.inf)
        needs_mesh[i] = may_hit_mesh(s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], t[i])
    return t, kind, index, needs_mesh


@jit_parallel
def _occluded_analytic_batch(s, o, d, tmax):
    n = d.shape[0]
    blocked = np.empty(n, dtype=np.bool_)
    needs_mesh = np.empty(n, dtype=np.bool_)
    for i in prange(n):
        blocked[i] = occluded_analytic(s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], tmax[i])
        needs_mesh[i] = (not blocked[i]) and may_hit_mesh(
            s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], tmax[i]
        )
    return blocked, needs_mesh


class RayTracer:
    """Closest-hit and occlusion queries against a compiled scene.

    Parameters
    ----------
    arrays : SceneArrays
        From :meth:`lightprobe.geometry.scene.Scene.compile`.
    threads : int
        Python threads that share each Embree batch (Embree releases the GIL).
    """

    def __init__(self, arrays: SceneArrays, *, threads: int = 2):
        self.arrays = arrays
        self.threads = max(1, int(threads))
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self.embree_rays = 0
        self.embree_seconds = 0.0
        #: set to a list to keep a copy of every Embree batch: ("occluded" | "intersect", origins, dirs, tfar)
        self.record: list | None = None
        self._scene = None
        if arrays.mesh_faces.shape[0]:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh

            self._scene = rtcore_scene.EmbreeScene(robust=True)
            vertices = arrays.mesh_vertices.astype(np.float32)
            for g in range(arrays.mesh_face_start.shape[0] - 1):
                faces = arrays.mesh_faces[arrays.mesh_face_start[g] : arrays.mesh_face_start[g + 1]]
                # each mesh is its own Embree geometry, so geomID is the mesh index
                TriangleMesh(self._scene, np.ascontiguousarray(vertices[faces]))
            # build the BVH now rather than inside the first timed query
            self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    def __del__(self):
        self.close()

    # --- Embree batches -----------------------------------------------------------------------------------------
    def _split(self, n: int) -> list[slice]:
        if self._pool is None or n < 2 * MIN_CHUNK:
            return [slice(0, n)]
        edges = np.linspace(0, n, self.threads + 1).astype(int)
        return [slice(int(a), int(b)) for a, b in itertools.pairwise(edges)]

    def _run(self, fn, n: int):
        parts = self._split(n)
        if len(parts) == 1:
            return [fn(parts[0])]
        return list(self._pool.map(fn, parts))

    def embree_occluded(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray | None = None) -> np.ndarray:
        """Boolean (N,): does a mesh block the segment (0, tfar)?  Inputs float32 (N, 3)."""
        n = origins.shape[0]
        if self._scene is None or n == 0:
            return np.zeros(n, dtype=bool)
        if self.record is not None:
            self.record.append(("occluded", origins.copy(), dirs.copy(), None if tfar is None else tfar.copy()))
        start = time.perf_counter()

        def work(sl):
            dist = None if tfar is None else np.ascontiguousarray(tfar[sl], dtype=np.float32)
            return self._scene.run(origins[sl], dirs[sl], dists=dist, query="OCCLUDED") != -1

        result = np.concatenate(self._run(work, n))
        self.embree_rays += n
        self.embree_seconds += time.perf_counter() - start
        return result

    def embree_intersect(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray):
        """Closest mesh hit closer than tfar: (t, mesh index, face, b1, b2), mesh index -1 for none."""
        n = origins.shape[0]
        if self.record is not None:
            self.record.append(("intersect", origins.copy(), dirs.copy(), tfar.copy()))
        start = time.perf_counter()

        def work(sl):
            dist = np.ascontiguousarray(tfar[sl], dtype=np.float32)
            r = self._scene.run(origins[sl], dirs[sl], dists=dist, output=1)
            return r["tfar"], r["geomID"], r["primID"], r["u"], r["v"]

        parts = self._run(work, n)
        result = tuple(np.concatenate([p[k] for p in parts]) for k in range(5))
        self.embree_rays += n
        self.embree_seconds += time.perf_counter() - start
        return result

    # --- full queries (NumPy in, NumPy out) ------------------------------------------------------------------------
    def intersect(self, origins, dirs):
        """Closest hit of each ray: (t, kind, index, prim, b1, b2); kind MISS/MESH/SPHERE/RECT, t = inf on a miss.

        ``dirs`` must be unit vectors.  For meshes ``index`` is the mesh, ``prim`` the face within it and (b1, b2)
        the barycentrics of vertices 1 and 2.
        """
        o = np.ascontiguousarray(origins, dtype=np.float64)
        d = np.ascontiguousarray(dirs, dtype=np.float64)
        t, kind, index, needs = _closest_analytic_batch(self.arrays, o, d)
        n = d.shape[0]
        prim = np.full(n, -1, dtype=np.int64)
        b1 = np.zeros(n)
        b2 = np.zeros(n)
        self.add_mesh_hits(o, d, needs, t, kind, index, prim, b1, b2)
        kind[~np.isfinite(t)] = MISS
        return t, kind, index, prim, b1, b2

    def add_mesh_hits(self, origins, dirs, needs, t, kind, index, prim, b1, b2) -> None:
        """Trace the rays flagged in ``needs`` against the meshes, closer than their current ``t`` (the nearest
        analytic hit), and write the mesh hits found into the hit arrays in place.

        ``origins`` is (N, 3), or one (3,) origin shared by every ray (a pinhole camera).
        """
        sel = np.nonzero(needs)[0]
        if sel.size == 0 or self._scene is None:
            return
        tfar = np.where(np.isfinite(t[sel]), t[sel], 3e38).astype(np.float32)
        o = np.asarray(origins)
        if o.ndim == 1:
            o32 = np.ascontiguousarray(np.broadcast_to(o.astype(np.float32), (sel.size, 3)))
        else:
            o32 = o[sel].astype(np.float32)
        mt, geom, face, u, v = self.embree_intersect(o32, dirs[sel].astype(np.float32), tfar)
        hit = geom != -1
        rows = sel[hit]
        t[rows] = mt[hit]
        kind[rows] = MESH
        index[rows] = geom[hit]
        prim[rows] = face[hit]
        b1[rows] = u[hit]
        b2[rows] = v[hit]

    def occluded(self, origins, dirs, tmax=None) -> np.ndarray:
        """Boolean (N,): is anything hit on the segment (0, tmax) (default: to infinity)?"""
        o = np.ascontiguousarray(origins, dtype=np.float64)
        d = np.ascontiguousarray(dirs, dtype=np.float64)
        tm = (
            np.full(d.shape[0], np.inf)
            if tmax is None
            else np.broadcast_to(np.asarray(tmax, dtype=np.float64), (d.shape[0],)).copy()
        )
        blocked, needs = _occluded_analytic_batch(self.arrays, o, d, tm)
        sel = np.nonzero(needs)[0]
        if sel.size and self._scene is not None:
            tfar = np.where(np.isfinite(tm[sel]), tm[sel], 3e38).astype(np.float32)
            blocked[sel] = self.embree_occluded(o[sel].astype(np.float32), d[sel].astype(np.float32), tfar)
        return blocked
