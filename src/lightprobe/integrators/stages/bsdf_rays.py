"""Stage 4, BSDF rays: what each BSDF (or hemisphere) direction sees, and the lights' density there for MIS.

In a scene without emissive surfaces a BSDF ray can only see the infinite lights, and only if nothing blocks it: it
becomes a shadow ray toward infinity (the shadow stages decide), and this stage gives it the radiance and the light
density of its direction.  With the environment map as the only light that is its lat-long coordinates (looked up by
the radiance stage) and its density under MIS (``environment_coords`` one slot at a time, ``environment_coords_lanes``
8 at a time in vector IR); with directional lights too, ``infinite_lights`` weighs each infinite light's radiance
with its own MIS weight.

In a scene with emissive surfaces the ray must know what it hits first: ``nearest_analytic`` finds the nearest
sphere or rectangle (and flags the rays that may reach a mesh before it), ``nearest_mesh`` asks Embree for those,
and ``what_bsdf_rays_see`` takes the radiance of what was hit -- an emitter's, seen from the point the ray itself
hit, weighed against the density of *that* point under light sampling (Mitsuba 3's ``direct``: a second
intersection from another origin can miss a small light's edge, decisions.md 68), the infinite lights' if nothing
was hit, nothing from an ordinary surface -- and needs no shadow ray.

Outside environment-alone scenes this stage weighs the radiance itself (it knows which lights the ray meets), and
the finish stage takes it as it is (``PassConstants.bsdf_weighed``).
"""

from __future__ import annotations

import numpy as np

from ..._numba import jit_body, jit_inline
from ...emitters.envmap import env_coords, env_pdf_at
from ...emitters.lights import area_pdf_at, emitted, infinite_radiance, light_pdf_of
from ...emitters.selection import selector_pmf
from ...geometry.embree import FAR as MESH_FAR
from ...geometry.embree import closest_mesh_hit
from ...geometry.intersect import MESH, MISS, closest_analytic, may_hit_mesh, ray_offset, surface
from ...simd import LANES
from ..techniques import ENV, MIS, SLOT_BSDF, SLOT_HEMI, SLOT_LIGHT, SLOT_NONE, bsdf_share
from .environment_lanes import env_coords_block
from .ray_lanes import CROSSED, HIT_INDEX, HIT_KIND, HIT_T, put_ray, shape_tests
from .setup import emitter_of

__all__ = [
    "environment_coords",
    "environment_coords_lanes",
    "infinite_lights",
    "nearest_analytic",
    "nearest_analytic_lanes",
    "nearest_mesh",
    "non_light_blocks",
    "what_bsdf_rays_see",
]


def non_light_blocks(c, cams, slots):
    """Items of ``environment_coords_lanes``: blocks of 8 of the slots that are not light samples -- under MIS a
    camera sample's first n_bsdf, under ``env`` none, else all m --, numbered over the pass's camera samples, so
    that the lanes hold no light samples (decisions.md 46)."""
    count = c.n_bsdf if c.strategy == MIS else (0 if c.strategy == ENV else c.m)
    return (cams.t.shape[0] * count + LANES - 1) // LANES


@jit_body
def environment_coords_lanes(env, c, cams, slots, lo, hi):
    """Blocks lo .. hi - 1 of 8 BSDF or hemisphere slots: lat-long coordinates and, under MIS, the environment's
    bilinear density."""
    count = c.n_bsdf if c.strategy == MIS else (0 if c.strategy == ENV else c.m)
    mis = c.strategy == MIS
    for block in range(lo, hi):
        env_coords_block(
            slots.state, cams.material, c.compensate, c.m, mis, slots.wdir, env.to_env, env.luminance,
            env.node_sines, env.marginal_cdf, env.comp_marginal_cdf, env.comp_offset, slots.uv, slots.light_pdf, 0,
            count, block * LANES,
        )  # fmt: skip


@jit_body
def environment_coords(env, c, cams, slots, lo, hi):
    """Slots lo .. hi - 1: lat-long coordinates of every live slot's direction (light samples have theirs already),
    and the environment's density for BSDF samples under MIS."""
    mis = c.strategy == MIS
    for r in range(lo, hi):
        st = slots.state[r]
        if st == SLOT_NONE or st == SLOT_LIGHT:
            continue
        u, v, cos_theta = env_coords(env, slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2])
        slots.uv[r, 0] = u
        slots.uv[r, 1] = v
        if mis and st == SLOT_BSDF:
            slots.light_pdf[r] = env_pdf_at(env, c.compensate[cams.material[r // c.m]], u, v, cos_theta)


@jit_body
def infinite_lights(env, lights, sel, c, cams, slots, lo, hi):
    """Slots lo .. hi - 1: a BSDF or hemisphere ray that may escape sees every infinite light, each weighed with
    its own density (the selector's probability x the light's pdf there); the shadow stages decide whether it
    escapes.  Rays no infinite light meets are dropped."""
    m = c.m
    for r in range(lo, hi):
        st = slots.state[r]
        if st != SLOT_BSDF and st != SLOT_HEMI:
            continue
        k = r // m
        _weigh_escaping(env, lights, sel, c, cams, slots, r, k)


@jit_inline
def _weigh_escaping(env, lights, sel, c, cams, slots, r, k):
    """slots.radiance[r] = sum over the infinite lights of L_i w_i, w_i = bsdf_share(p_bsdf, p_l(i) pdf_i), for the
    ray of slot r leaving camera sample k's point; state SLOT_NONE if it is black."""
    wx, wy, wz = slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2]
    px, py, pz = cams.point[k, 0], cams.point[k, 1], cams.point[k, 2]
    nx, ny, nz = cams.gnormal[k, 0], cams.gnormal[k, 1], cams.gnormal[k, 2]
    compensated = c.compensate[cams.material[k]]
    r_sum = g_sum = b_sum = 0.0
    for light in range(sel.n_bounded, lights.kind.shape[0]):
        lr, lg, lb = infinite_radiance(lights, env, light, wx, wy, wz)
        if lr == 0.0 and lg == 0.0 and lb == 0.0:
            continue
        share = 1.0 / c.m
        if c.strategy == MIS:
            # a light the selector never picks here (a constant sky for a compensated receiver: decisions.md 98)
            # has no light-sample density to weigh against, and its own density is not looked up
            p_light = selector_pmf(sel, px, py, pz, nx, ny, nz, light, compensated)
            if p_light > 0.0:
                p_light *= light_pdf_of(
                    lights, env, light, c.light_strategy, compensated, px, py, pz, nx, ny, nz, wx, wy, wz
                )
            share = bsdf_share(c, slots.tpdf[r], p_light)
        r_sum += lr * share
        g_sum += lg * share
        b_sum += lb * share
    if r_sum == 0.0 and g_sum == 0.0 and b_sum == 0.0:
        slots.state[r] = SLOT_NONE
        return
    slots.radiance[r, 0], slots.radiance[r, 1], slots.radiance[r, 2] = r_sum, g_sum, b_sum


@jit_inline
def _traced(slots, r):
    """Slot r is a BSDF or hemisphere sample, whose ray looks for its nearest hit."""
    return slots.state[r] == SLOT_BSDF or slots.state[r] == SLOT_HEMI


@jit_inline
def _bsdf_ray_into(c, cams, slots, r):
    """Slot r's ray from its camera sample's point, offset by the point's error bound (into ``ray_o``): (origin,
    direction)."""
    k = r // c.m
    wx, wy, wz = slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2]
    qx, qy, qz = ray_offset(
        cams.point[k, 0], cams.point[k, 1], cams.point[k, 2], cams.gnormal[k, 0], cams.gnormal[k, 1],
        cams.gnormal[k, 2], cams.point_error[k], wx, wy, wz,
    )  # fmt: skip
    slots.ray_o[r, 0], slots.ray_o[r, 1], slots.ray_o[r, 2] = qx, qy, qz
    return qx, qy, qz, wx, wy, wz


@jit_body
def nearest_analytic(s, c, cams, slots, lo, hi):
    """Slots lo .. hi - 1: a BSDF or hemisphere ray's origin (offset from the surface by the point's error bound)
    and its nearest analytic hit; ``hit_mesh`` where a mesh may be nearer."""
    if slots.hit_t.shape[0] == 0:  # never without the hit record (pass_state.py)
        return
    for r in range(lo, hi):
        if not _traced(slots, r):
            continue
        qx, qy, qz, wx, wy, wz = _bsdf_ray_into(c, cams, slots, r)
        th, kh, ih = closest_analytic(s, qx, qy, qz, wx, wy, wz, np.inf)
        slots.hit_t[r], slots.hit_kind[r], slots.hit_index[r] = th, kh, ih
        slots.hit_prim[r] = 0
        slots.hit_b1[r] = 0.0
        slots.hit_b2[r] = 0.0
        slots.hit_mesh[r] = may_hit_mesh(s, qx, qy, qz, wx, wy, wz, th)


@jit_body
def nearest_analytic_lanes(s, c, cams, slots, worker, lo, hi):
    """Blocks lo .. hi - 1 of 8 slots: as ``nearest_analytic``, the rays built one at a time and their shape tests
    made 8 at a time (``ray_lanes.ray_block``).  Not for a scene with a shape hierarchy, whose rays walk it one at a
    time in ``nearest_analytic`` (the plan picks that stage there: ``pipeline.Plan.shape_tree``)."""
    if slots.hit_t.shape[0] == 0:  # never without the hit record (pass_state.py)
        return
    n = slots.state.shape[0]
    block = c.lane_rays[worker]
    lanes = c.packet_slots[worker]  # the slot of each lane
    end = min(hi * LANES, n)
    count = 0
    for r in range(lo * LANES, end + 1):  # the traced slots gathered as they are found (decisions.md 60, 101)
        if r < end:
            if not _traced(slots, r):
                continue
            qx, qy, qz, wx, wy, wz = _bsdf_ray_into(c, cams, slots, r)
            put_ray(block, count, qx, qy, qz, wx, wy, wz, np.inf)
            lanes[count] = r
            count += 1
        if count < LANES and (r < end or count == 0):
            continue
        shape_tests(block, count, s.spheres, s.rects, s.mesh_bounds, s.mesh_spheres)
        for lane in range(count):
            r = lanes[lane]
            slots.hit_t[r] = block[HIT_T, lane]
            slots.hit_kind[r] = np.int64(block[HIT_KIND, lane])
            slots.hit_index[r] = np.int64(block[HIT_INDEX, lane])
            slots.hit_prim[r] = 0
            slots.hit_b1[r] = 0.0
            slots.hit_b2[r] = 0.0
            slots.hit_mesh[r] = block[CROSSED, lane] != 0.0
        count = 0


@jit_body
def nearest_mesh(c, slots, worker, lo, hi):
    """Slots lo .. hi - 1 flagged ``hit_mesh``: the nearest mesh hit through Embree, where it is nearer than the
    analytic one (the flagged slots are found as the chunk is scanned: decisions.md 60)."""
    if slots.hit_t.shape[0] == 0:  # never without the hit record (pass_state.py)
        return
    for r in range(lo, hi):
        if not slots.hit_mesh[r]:
            continue
        c.ray_counts[worker, 2] += 1
        far = slots.hit_t[r] if slots.hit_t[r] < np.inf else MESH_FAR
        mt, mesh, face, mb1, mb2 = closest_mesh_hit(
            c.mesh_scene, c.scratch[worker], slots.ray_o[r, 0], slots.ray_o[r, 1], slots.ray_o[r, 2], slots.wdir[r, 0],
            slots.wdir[r, 1], slots.wdir[r, 2], far,
        )  # fmt: skip
        if mesh >= 0:
            slots.hit_t[r], slots.hit_kind[r], slots.hit_index[r] = mt, MESH, mesh
            slots.hit_prim[r], slots.hit_b1[r], slots.hit_b2[r] = face, mb1, mb2


@jit_body
def what_bsdf_rays_see(s, env, lights, sel, c, cams, slots, lo, hi):
    """Slots lo .. hi - 1: the radiance each BSDF or hemisphere ray sees at its nearest hit, weighed for MIS; rays
    that hit an ordinary surface are dropped."""
    if slots.hit_t.shape[0] == 0:  # never without the hit record (pass_state.py)
        return
    m = c.m
    for r in range(lo, hi):
        st = slots.state[r]
        if st != SLOT_BSDF and st != SLOT_HEMI:
            continue
        k = r // m
        if slots.hit_kind[r] == MISS:
            _weigh_escaping(env, lights, sel, c, cams, slots, r, k)
            continue
        light = emitter_of(s, slots.hit_kind[r], slots.hit_index[r], slots.hit_prim[r])
        if light < 0:
            slots.state[r] = SLOT_NONE
            continue
        wx, wy, wz = slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2]
        hit = surface(
            s, slots.hit_kind[r], slots.hit_index[r], slots.hit_prim[r], slots.hit_b1[r], slots.hit_b2[r],
            slots.ray_o[r, 0], slots.ray_o[r, 1], slots.ray_o[r, 2], wx, wy, wz, slots.hit_t[r],
        )  # fmt: skip
        x = hit[0]
        lr, lg, lb = emitted(lights, light, x[0], x[1], x[2], wx, wy, wz)
        if lr == 0.0 and lg == 0.0 and lb == 0.0:
            slots.state[r] = SLOT_NONE
            continue
        share = 1.0 / m
        if c.strategy == MIS:
            px, py, pz = cams.point[k, 0], cams.point[k, 1], cams.point[k, 2]
            nx, ny, nz = cams.gnormal[k, 0], cams.gnormal[k, 1], cams.gnormal[k, 2]
            # the emitter's density at the point this ray hit (Mitsuba 3's direct: pdf_emitter_direction(si, ds)
            # with ds from the BSDF ray's own hit)
            compensated = c.compensate[cams.material[k]]
            p_light = selector_pmf(sel, px, py, pz, nx, ny, nz, light, compensated) * area_pdf_at(
                lights, light, c.light_strategy, px, py, pz, nx, ny, nz, x[0], x[1], x[2]
            )
            share = bsdf_share(c, slots.tpdf[r], p_light)
        slots.radiance[r, 0], slots.radiance[r, 1], slots.radiance[r, 2] = lr * share, lg * share, lb * share
