"""Ray queries: analytic shapes in Numba, triangle meshes in Embree 4 (its C API, :mod:`.embree`).

Embree has no per-ray tnear here (callers offset origins, see :func:`lightprobe.geometry.intersect.ray_offset`).
The render kernels call Embree themselves, one ray at a time; the batch methods below serve everything else
(the object-id pass, NumPy callers, tests) with the same calls, split among threads.

Closest-hit queries take a per-ray ``tfar`` (the nearest analytic hit), so Embree only reports closer triangles.
"""

from __future__ import annotations

import numpy as np

from .._numba import jit
from .._worksharing import in_threads
from ..errors import LightprobeError
from .embree import FAR, EmbreeScene, intersect_batch, new_scratch, occluded_batch
from .intersect import MESH, MISS, closest_analytic, may_hit_mesh, occluded_analytic
from .scene_arrays import SceneArrays

__all__ = ["RayTracer"]


@jit
def _closest_analytic_range(s, o, d, t, kind, index, needs_mesh, lo, hi):
    """Rays lo .. hi - 1: the nearest analytic hit, and whether a mesh may be nearer."""
    for i in range(lo, hi):
        t[i], kind[i], index[i] = closest_analytic(s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], np.inf)
        needs_mesh[i] = may_hit_mesh(s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], t[i])


@jit
def _occluded_analytic_range(s, o, d, tmax, blocked, needs_mesh, lo, hi):
    """Rays lo .. hi - 1: blocked by an analytic shape, or else whether a mesh may block them."""
    for i in range(lo, hi):
        blocked[i] = occluded_analytic(s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], tmax[i])
        needs_mesh[i] = (not blocked[i]) and may_hit_mesh(
            s, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], tmax[i]
        )


def _closest_analytic_batch(s, o, d):
    """(t, kind, index, needs_mesh) of rays (o, d) (float64 (N, 3)) against the analytic shapes of ``s`` (a range
    kernel in threads, not a ``prange`` loop: ``_worksharing.in_threads``)."""
    n = d.shape[0]
    t, kind, index = np.empty(n), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    needs_mesh = np.empty(n, dtype=np.bool_)
    in_threads(_closest_analytic_range, n, s, o, d, t, kind, index, needs_mesh)
    return t, kind, index, needs_mesh


def _occluded_analytic_batch(s, o, d, tmax):
    """(blocked, needs_mesh) of the segments (o, o + tmax d) against the analytic shapes of ``s``."""
    n = d.shape[0]
    blocked, needs_mesh = np.empty(n, dtype=np.bool_), np.empty(n, dtype=np.bool_)
    in_threads(_occluded_analytic_range, n, s, o, d, tmax, blocked, needs_mesh)
    return blocked, needs_mesh


class RayTracer:
    """Closest-hit and occlusion queries against a compiled scene.

    Parameters
    ----------
    arrays : SceneArrays
        From :meth:`lightprobe.scene.Scene.compile`.
    threads : int
        Kept for callers; Embree batches run in Numba's threads (``numba.set_num_threads``).
    """

    def __init__(self, arrays: SceneArrays, *, threads: int = 2):
        self.arrays = arrays
        self.threads = max(1, int(threads))
        self.embree_rays = 0  # rays traced by the batch methods (the render kernels count their own)
        #: the meshes' Embree scene (None without meshes); kernels take ``mesh_scene`` and ``scratch``
        self.embree: EmbreeScene | None = None
        self.scratch = new_scratch()
        if arrays.mesh_faces.shape[0]:
            self.embree = EmbreeScene(arrays.mesh_vertices, arrays.mesh_faces, arrays.mesh_face_start, arrays=arrays)

    def _require_open(self) -> None:
        if self.embree is None and self.arrays.mesh_faces.shape[0]:  # else every mesh would silently vanish
            raise LightprobeError("this RayTracer was closed; make a new one for the scene")

    @property
    def mesh_scene(self) -> int:
        """The ``RTCScene`` handle for kernels, 0 when there are no meshes."""
        self._require_open()
        return 0 if self.embree is None else self.embree.handle

    def close(self) -> None:
        if self.embree is not None:
            self.embree.close()
            self.embree = None

    # --- Embree batches -----------------------------------------------------------------------------------------
    def embree_occluded(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray | None = None) -> np.ndarray:
        """Boolean (N,): does a mesh block the segment (0, tfar)?  Inputs (N, 3), rounded to float32."""
        n = origins.shape[0]
        if self.embree is None or n == 0:
            self._require_open()
            return np.zeros(n, dtype=bool)
        far = np.full(n, FAR, np.float32) if tfar is None else np.asarray(tfar, np.float32)
        result = occluded_batch(self.mesh_scene, self.scratch, origins, dirs, far)
        self.embree_rays += n
        return result

    def embree_intersect(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray):
        """Closest mesh hit closer than tfar: (t, mesh index, face, b1, b2), mesh index -1 for none."""
        n = origins.shape[0]
        if self.embree is None or n == 0:
            self._require_open()
            return (np.asarray(tfar, np.float32).copy(), np.full(n, -1), np.full(n, -1), np.zeros(n, np.float32),
                    np.zeros(n, np.float32))  # fmt: skip
        result = intersect_batch(self.mesh_scene, self.scratch, origins, dirs, np.asarray(tfar, np.float32))
        self.embree_rays += n
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
        if sel.size == 0 or not self.mesh_scene:
            return
        tfar = np.where(np.isfinite(t[sel]), t[sel], FAR).astype(np.float32)
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
        if sel.size and self.mesh_scene:
            tfar = np.where(np.isfinite(tm[sel]), tm[sel], FAR).astype(np.float32)
            blocked[sel] = self.embree_occluded(o[sel].astype(np.float32), d[sel].astype(np.float32), tfar)
        return blocked
