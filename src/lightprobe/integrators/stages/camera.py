"""Stage 1, camera rays: each camera sample's ray (box filter with jitter) and its nearest hit.

Analytic shapes first, 8 rays at a time in vector IR (``ray_lanes.ray_block``, which also says whether a ray may
reach a mesh; one at a time through the shapes' hierarchy when the scene has one), then meshes through Embree where a
ray may reach a mesh's bounds before its analytic hit.  Meshes in the same loop: camera rays are coherent, and here
they cost 0.27 s of the peer scene's 64-spp render against 0.42 s in a loop of their own (the opposite of shadow
rays, decisions.md 30).  One ray at a time where the vector intrinsics do not compile (``camera_scalar``).
"""

from __future__ import annotations

import numpy as np

from ..._numba import jit_body, jit_inline
from ...geometry.camera import camera_ray
from ...geometry.embree import FAR as MESH_FAR
from ...geometry.embree import closest_mesh_hit
from ...geometry.intersect import MESH, closest_analytic, may_hit_mesh
from ...sampling.rng import SOBOL, sample_state, uniform_2d
from ...simd import LANES
from .ray_lanes import CROSSED, HIT_INDEX, HIT_KIND, HIT_T, put_ray, shape_tests
from .sobol_lanes import camera_numbers_block

__all__ = ["camera_blocks", "camera_lanes", "camera_lanes_tree", "camera_samples", "camera_scalar"]


def camera_samples(c, cams, slots):
    """The scalar stage's items: camera samples."""
    return cams.t.shape[0]


def camera_blocks(c, cams, slots):
    """The lanes stage's items: blocks of 8 camera samples."""
    return (cams.t.shape[0] + LANES - 1) // LANES


@jit_inline
def _ray_into(c, cams, k):
    """Camera sample k's ray direction, into dirs[k] (box filter with jitter)."""
    pixel = c.pixels[k // c.spp_pass]
    rs = sample_state(c.sampler, c.seed, pixel, c.sample_start + k % c.spp_pass)
    u0, u1 = uniform_2d(rs, 0)
    cams.dirs[k, 0], cams.dirs[k, 1], cams.dirs[k, 2] = camera_ray(c.cam, pixel, u0, u1)


@jit_inline
def _mesh_hit_into(s, c, cams, worker, k, may_hit):
    """Camera sample k's nearest mesh hit through Embree, where its ray may reach a mesh's bounds before its
    analytic hit t[k] (``may_hit``: ``may_hit_mesh``); the mesh hit replaces that one when nearer."""
    cams.prim[k] = 0
    cams.b1[k] = 0.0
    cams.b2[k] = 0.0
    ox, oy, oz = c.cam[0], c.cam[1], c.cam[2]
    dx, dy, dz = cams.dirs[k, 0], cams.dirs[k, 1], cams.dirs[k, 2]
    t = cams.t[k]
    if c.mesh_scene != 0 and may_hit:
        c.ray_counts[worker, 0] += 1
        far = t if t < np.inf else MESH_FAR
        mt, mesh, face, mb1, mb2 = closest_mesh_hit(c.mesh_scene, c.scratch[worker], ox, oy, oz, dx, dy, dz, far)
        if mesh >= 0:
            cams.t[k], cams.kind[k], cams.index[k] = mt, MESH, mesh
            cams.prim[k], cams.b1[k], cams.b2[k] = face, mb1, mb2


@jit_inline
def _nearest_hit_into(s, c, cams, worker, k):
    """Camera sample k's nearest hit, one ray at a time: analytic shapes, then meshes."""
    ox, oy, oz = c.cam[0], c.cam[1], c.cam[2]
    dx, dy, dz = cams.dirs[k, 0], cams.dirs[k, 1], cams.dirs[k, 2]
    t, cams.kind[k], cams.index[k] = closest_analytic(s, ox, oy, oz, dx, dy, dz, np.inf)
    cams.t[k] = t
    _mesh_hit_into(s, c, cams, worker, k, may_hit_mesh(s, ox, oy, oz, dx, dy, dz, t))


@jit_inline
def _block_rays(c, cams, start, stop):
    """The directions of camera samples start .. stop - 1, into dirs."""
    dirs = cams.dirs
    if c.sampler == SOBOL:
        # the rays' positions in their pixels 8 at a time (sampling/sobol_lanes.py), into dirs until the directions
        # replace them: the same bits as uniform_2d
        camera_numbers_block(dirs, c.seed, c.pixels, c.spp_pass, c.sample_start, start)
        for k in range(start, stop):
            dirs[k, 0], dirs[k, 1], dirs[k, 2] = camera_ray(c.cam, c.pixels[k // c.spp_pass], dirs[k, 0], dirs[k, 1])
    else:
        for k in range(start, stop):
            _ray_into(c, cams, k)


@jit_body
def camera_lanes(s, c, cams, worker, lo, hi):
    """Blocks lo .. hi - 1 of 8 camera samples, the analytic shapes tested 8 rays at a time (ray_lanes.py): a scene
    without a shape hierarchy."""
    n = cams.t.shape[0]
    dirs = cams.dirs
    for block in range(lo, hi):
        start = block * LANES
        stop = min(start + LANES, n)
        _block_rays(c, cams, start, stop)
        rays = c.lane_rays[worker]
        for k in range(start, stop):
            put_ray(rays, k - start, c.cam[0], c.cam[1], c.cam[2], dirs[k, 0], dirs[k, 1], dirs[k, 2], np.inf)
        shape_tests(rays, stop - start, s.spheres, s.rects, s.mesh_bounds, s.mesh_spheres)
        for k in range(start, stop):
            lane = k - start
            cams.t[k] = rays[HIT_T, lane]
            cams.kind[k] = np.int64(rays[HIT_KIND, lane])
            cams.index[k] = np.int64(rays[HIT_INDEX, lane])
            _mesh_hit_into(s, c, cams, worker, k, rays[CROSSED, lane] != 0.0)


@jit_body
def camera_lanes_tree(s, c, cams, worker, lo, hi):
    """Blocks lo .. hi - 1 of 8 camera samples, their directions as :func:`camera_lanes` makes them, each ray then
    walking the shapes' hierarchy (geometry/shape_bvh.py: a scene of many spheres and rectangles).  A stage of its
    own so that the other scenes' camera stage carries no hierarchy walk: it was 3.6 s of the demo's 43 s of
    compiling (decisions.md 112)."""
    n = cams.t.shape[0]
    for block in range(lo, hi):
        start = block * LANES
        stop = min(start + LANES, n)
        _block_rays(c, cams, start, stop)
        for k in range(start, stop):
            _nearest_hit_into(s, c, cams, worker, k)


@jit_body
def camera_scalar(s, c, cams, worker, lo, hi):
    """Camera samples lo .. hi - 1, one ray at a time."""
    for k in range(lo, hi):
        _ray_into(c, cams, k)
        _nearest_hit_into(s, c, cams, worker, k)
