"""Stage 6, shadow rays: is anything between a shading point and the light its slot's contribution came from?

A slot flagged ``TEST_ANALYTIC`` by the finish stage has a shadow ray (:func:`shadow_ray`): from the shading point
offset by its error bound along the geometric normal (``intersect.ray_offset``), along the slot's direction, to
infinity (the environment, a directional light, a BSDF ray in a scene without emissive surfaces) or to the sampled
point of a bounded light, that point moved toward the shading point by its own error bound, the segment stopping
``SHADOW_EPSILON`` of its length short (pbrt-v4's ``SpawnRayTo`` and ``ShadowEpsilon``).

``analytic_shadows`` tests it against the spheres and rectangles (``BLOCKED``), then the meshes' bounding boxes and
spheres (``TEST_MESH`` for the mesh stage, or ``VISIBLE``).  ``analytic_shadows_lanes`` builds the same rays one at a
time and tests them 8 at a time in vector IR (``ray_lanes.ray_block``), for every scene without a shape hierarchy (in
the finish stage, one ray at a time with early exits, these tests were half of its time, decisions.md 49; one stage
for bounded and unbounded rays since decisions.md 101).
``mesh_shadows`` traces the ``TEST_MESH`` rays through Embree 8 at a time where its 8-ray packets are native
(decisions.md 55), ``mesh_shadows_single`` one at a time elsewhere; they run in loops of their own, where the
shading work does not evict Embree's BVH between rays (decisions.md 30), and gather their rays as they scan the
slots (decisions.md 60).  Which rays share a packet changes no answer.
"""

from __future__ import annotations

import math

import numpy as np

from ..._numba import jit_body, jit_inline
from ...emitters.area import light_normal, light_point_error
from ...emitters.lights import is_positional
from ...geometry.embree import FAR as MESH_FAR
from ...geometry.embree import PACKET, mesh_occluded, occluded_packet, packet_ray, packet_words
from ...geometry.intersect import blocked_by_mesh_core, may_hit_mesh, occluded_analytic, ray_offset
from ...simd import LANES
from ..techniques import BLOCKED, SLOT_LIGHT, TEST_ANALYTIC, TEST_MESH, VISIBLE
from .ray_lanes import CORE, CROSSED, HIT_T, TMAX, put_ray, shape_tests

__all__ = [
    "SHADOW_EPSILON",
    "analytic_shadows",
    "analytic_shadows_lanes",
    "mesh_shadows",
    "mesh_shadows_single",
    "ray_to_light",
    "shadow_ray",
]

# A shadow ray to a sampled light point stops this fraction of its length short of the point moved off the light
# (pbrt-v4's ShadowEpsilon, 1e-4 in float32): the error bounds make it safe, the margin lets the bounding-box tests
# see that a ray ending under a flat emissive mesh does not reach it (without it, rays to a ring of light triangles
# went to Embree 13x as often, to find nothing).
SHADOW_EPSILON = 1e-5


@jit_inline
def ray_to_light(lights, light, px, py, pz, qx, qy, qz, wx, wy, wz, dist):
    """The shadow ray from origin q (p offset by its error bound) to the point x = p + dist w sampled on ``light``,
    x moved toward p by its own error bound along the light's normal: (origin, unit direction, length less
    SHADOW_EPSILON of it).  A point or spot light is its own position, with no surface to offset from."""
    x, y, z = px + dist * wx, py + dist * wy, pz + dist * wz
    if is_positional(lights, light):
        tx, ty, tz = lights.geom[light, 0] - qx, lights.geom[light, 1] - qy, lights.geom[light, 2] - qz
        length = math.sqrt(tx * tx + ty * ty + tz * tz)
        return qx, qy, qz, tx / length, ty / length, tz / length, length * (1.0 - SHADOW_EPSILON)
    n = light_normal(lights, light, x, y, z)
    eps = light_point_error(lights, light, x, y, z, n)
    if n[0] * wx + n[1] * wy + n[2] * wz > 0.0:  # p is behind the normal: the end moves against it
        eps = -eps
    tx, ty, tz = x + eps * n[0] - qx, y + eps * n[1] - qy, z + eps * n[2] - qz
    length = math.sqrt(tx * tx + ty * ty + tz * tz)
    return qx, qy, qz, tx / length, ty / length, tz / length, length * (1.0 - SHADOW_EPSILON)


@jit_inline
def shadow_ray(lights, c, cams, slots, r):
    """Slot r's shadow ray: (origin x, y, z, unit direction x, y, z, length; inf: unbounded)."""
    k = r // c.m
    px, py, pz = cams.point[k, 0], cams.point[k, 1], cams.point[k, 2]
    wx, wy, wz = slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2]
    qx, qy, qz = ray_offset(
        px, py, pz, cams.gnormal[k, 0], cams.gnormal[k, 1], cams.gnormal[k, 2], cams.point_error[k], wx, wy, wz
    )
    if slots.seg.shape[0] > 0 and slots.state[r] == SLOT_LIGHT and slots.seg[r] < math.inf:  # seg: bounded lights
        # a point x on a bounded light: the shadow ray leaves the offset origin aimed at x moved toward p by x's own
        # error bound, and ends there (pbrt-v4's SpawnRayTo offsets both ends; from the offset origin along the
        # original direction, a grazing ray would meet the light's plane before the segment ends and shadow itself)
        return ray_to_light(lights, slots.light[r], px, py, pz, qx, qy, qz, wx, wy, wz, slots.seg[r])
    return qx, qy, qz, wx, wy, wz, math.inf


@jit_body
def analytic_shadows(s, lights, c, cams, slots, lo, hi):
    """Slots lo .. hi - 1 flagged TEST_ANALYTIC, one at a time: BLOCKED by a sphere, a rectangle or a closed
    mesh's inner ball, else TEST_MESH where a mesh's bounds are crossed, else VISIBLE."""
    for r in range(lo, hi):
        if slots.flags[r] != TEST_ANALYTIC:
            continue
        qx, qy, qz, wx, wy, wz, tmax = shadow_ray(lights, c, cams, slots, r)
        if occluded_analytic(s, qx, qy, qz, wx, wy, wz, tmax) or (
            tmax == math.inf and blocked_by_mesh_core(s, qx, qy, qz, wx, wy, wz)
        ):
            slots.flags[r] = BLOCKED
        else:
            slots.flags[r] = TEST_MESH if may_hit_mesh(s, qx, qy, qz, wx, wy, wz, tmax) else VISIBLE


@jit_body
def analytic_shadows_lanes(s, lights, c, cams, slots, worker, lo, hi):
    """Blocks lo .. hi - 1 of 8 slots, shadow rays of any kind (to a light's sampled point or unbounded): as
    ``analytic_shadows``, each ray built by ``shadow_ray`` and the shape tests made 8 rays at a time
    (``ray_lanes.ray_block``).  Not for a scene with a shape hierarchy, whose rays walk it one at a time in
    ``analytic_shadows`` (the plan picks that stage there: ``pipeline.Plan.shape_tree``)."""
    n = slots.flags.shape[0]
    block = c.lane_rays[worker]
    lanes = c.packet_slots[worker]  # the slot of each lane
    end = min(hi * LANES, n)
    count = 0
    for r in range(lo * LANES, end + 1):  # the flagged slots gathered as they are found (decisions.md 60, 101)
        if r < end:
            if slots.flags[r] != TEST_ANALYTIC:
                continue
            qx, qy, qz, wx, wy, wz, tmax = shadow_ray(lights, c, cams, slots, r)
            put_ray(block, count, qx, qy, qz, wx, wy, wz, tmax)
            lanes[count] = r
            count += 1
        if count < LANES and (r < end or count == 0):
            continue
        shape_tests(block, count, s.spheres, s.rects, s.mesh_bounds, s.mesh_spheres)
        for lane in range(count):
            r = lanes[lane]
            tmax = block[TMAX, lane]
            # occluded_analytic: a hit before tmax; blocked_by_mesh_core: only for a ray to infinity
            if block[HIT_T, lane] < tmax or (tmax == math.inf and block[CORE, lane] != 0.0):
                slots.flags[r] = BLOCKED
            else:  # no hit: the mesh test's bound, HIT_T, is tmax (may_hit_mesh(..., tmax))
                slots.flags[r] = TEST_MESH if block[CROSSED, lane] != 0.0 else VISIBLE
        count = 0


@jit_body
def mesh_shadows(lights, c, cams, slots, worker, lo, hi):
    """Slots lo .. hi - 1 flagged TEST_MESH through Embree 8 at a time: each becomes VISIBLE or BLOCKED."""
    packet = packet_words(c.scratch[worker])
    floats = packet.view(np.float32)
    lanes = c.packet_slots[worker]  # the slots in the packet
    count = 0
    for r in range(lo, hi + 1):
        if r < hi:
            if slots.flags[r] != TEST_MESH:
                continue
            qx, qy, qz, wx, wy, wz, tmax = shadow_ray(lights, c, cams, slots, r)
            packet_ray(packet, floats, count, qx, qy, qz, wx, wy, wz, tmax if tmax < MESH_FAR else MESH_FAR)
            lanes[count] = r
            count += 1
        if count == PACKET or (r == hi and count > 0):  # a full packet, or the chunk's last rays
            blocked = occluded_packet(c.mesh_scene, packet, floats, count)
            c.ray_counts[worker, 1] += count
            for i in range(count):
                slots.flags[lanes[i]] = BLOCKED if blocked >> i & 1 else VISIBLE
            count = 0


@jit_body
def mesh_shadows_single(lights, c, cams, slots, worker, lo, hi):
    """``mesh_shadows`` one ray at a time: where Embree's 8-ray packets are not native."""
    for r in range(lo, hi):
        if slots.flags[r] != TEST_MESH:
            continue
        qx, qy, qz, wx, wy, wz, tmax = shadow_ray(lights, c, cams, slots, r)
        c.ray_counts[worker, 1] += 1
        far = tmax if tmax < MESH_FAR else MESH_FAR
        blocked = mesh_occluded(c.mesh_scene, c.scratch[worker], qx, qy, qz, wx, wy, wz, far)
        slots.flags[r] = BLOCKED if blocked else VISIBLE
