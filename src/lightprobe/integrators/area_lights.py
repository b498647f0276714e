"""The wavefront renderer's shading stages for scenes with area lights (the environment, if any, is one more light).

Scenes lit by an environment map alone keep the measured four-stage environment path of
:mod:`lightprobe.integrators.wavefront`; a scene with emitters shades here instead:

1. ``_lights_setup``: hit points and frames; a camera ray that hits an emitter sees its radiance; BSDF and
   hemisphere directions get their nearest analytic hit (and a flag if a mesh may be nearer); each light slot
   picks a light with the selector, with the first number of its own 2D pair, and samples it with what is left of
   that number and the pair's second (one pick per group of ``n_per_light`` > 1 slots from that group's own 1D
   dimension, so a pick never shifts the dimensions of other samples), with the light strategy (a point or spot
   light: its one direction, MIS weight 1).
2. ``_lights_mesh_hits``: Embree closest hits for the BSDF directions that may reach a mesh.
3. ``_lights_finish``: a BSDF or hemisphere direction counts the radiance of what it hits: an emitter's (MIS
   weight from p_l x pdf_li of *that* emitter), the environment's if it escapes, nothing if it hits an ordinary
   surface (so it needs no shadow ray).  A light sample casts a shadow ray over the *segment* to the sampled
   point (tested against analytic shapes here, flagged TEST_MESH with its segment's ``tfar`` otherwise).
4. ``_lights_mesh_shadows``: Embree occlusion for the shadow rays flagged TEST_MESH.

Stages 2 and 4 exist only for scenes with meshes.  They call Embree from inside the kernel, in loops of their own,
as the environment path does (decisions.md 30).

The estimator of a light slot is the lecture's 1/(KN) sum f L cos / (p_l p(x')), combined with BSDF samples by the
balance or power heuristic on sample-count-weighted densities (n_bsdf p_bsdf against K N p_l p_li).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._memory import fresh_array
from .._numba import jit, jit_inline, jit_parallel, prange
from .._worksharing import claim_range
from ..bsdfs.dispatch import bsdf_eval, bsdf_pdf
from ..emitters.area import (
    LIGHT_POINT,
    light_normal,
    light_pdf_at,
    light_point_error,
    light_radiance,
    light_sample,
)
from ..emitters.envmap import env_eval, env_eval_pdf, env_sample
from ..emitters.selection import select_light, selector_pmf
from ..geometry.embree import FAR as MESH_FAR
from ..geometry.embree import closest_mesh_hit, mesh_occluded
from ..geometry.frame import to_local, to_world
from ..geometry.intersect import (
    MESH,
    MISS,
    RECT,
    SPHERE,
    closest_analytic,
    may_hit_mesh,
    occluded_analytic,
    ray_offset,
    surface,
)
from ..sampling.mis import mis_weight_over, mis_weight_share
from ..sampling.rng import group_slot, sample_state, uniform, uniform_2d
from .techniques import (
    BLOCKED,
    BRDF,
    ENV,
    MIS,
    NONE,
    SLOT_BSDF,
    SLOT_ENV,
    SLOT_NONE,
    TEST_MESH,
    VISIBLE,
    load_shading_frame,
    sample_direction,
    store_shading_frame,
    technique_slot,
)

__all__ = ["slot_buffers", "stages"]

SLOT_LIGHT = SLOT_ENV  # a light sample: the environment's or an area light's


@jit_inline
def emitter_of(s, kind, index, prim):
    """Row of the light table for a surface hit, or -1 if the surface does not emit."""
    if kind == SPHERE:
        return s.sphere_light[index]
    if kind == RECT:
        return s.rect_light[index]
    if kind == MESH:
        start = s.mesh_light_start[index]
        return start + prim if start >= 0 else -1
    return -1


@jit_inline
def _emitted(s, lights, hit, p, dx, dy, dz):
    """Radiance a ray in direction d sees at its hit ``hit`` = (kind, index, prim, ...) with point p: the emitter's
    on the side its normal at p faces (0 for surfaces that do not emit).  From the hit itself, never a second
    intersection (which from another origin can miss a small light's edge)."""
    light = emitter_of(s, hit[0], hit[1], hit[2])
    if light < 0:
        return 0.0, 0.0, 0.0
    n = light_normal(lights, light, p[0], p[1], p[2])
    return light_radiance(lights, light, -(n[0] * dx + n[1] * dy + n[2] * dz))


# A shadow ray to a sampled light point stops this fraction of its length short of the point moved off the light
# (pbrt-v4's ShadowEpsilon, 1e-4 in float32): the error bounds make it safe, the margin lets the bounding-box tests
# see that a ray ending under a flat emissive mesh does not reach it (without it, rays to a ring of light triangles
# went to Embree 13x as often, to find nothing).
SHADOW_EPSILON = 1e-5


@jit_inline
def is_delta(lights, light):
    """Whether row ``light`` is a point or spot light (the environment's index lies past the table's rows)."""
    return light < lights.kind.shape[0] and lights.kind[light] >= LIGHT_POINT


@jit_inline
def _ray_to_light(lights, light, px, py, pz, qx, qy, qz, wx, wy, wz, dist):
    """The shadow ray from origin q (p offset by its error bound) to the point x = p + dist w sampled on ``light``,
    x moved toward p by its own error bound along the light's normal: (origin, unit direction, length less
    SHADOW_EPSILON of it).  A point or spot light is its own position, with no surface to offset from."""
    x, y, z = px + dist * wx, py + dist * wy, pz + dist * wz
    if lights.kind[light] >= LIGHT_POINT:
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


@jit
def _pick_slot(state, n_bsdf, n_per_light, m, strategy, j):
    """The (sample state, slot) whose 1D number picks the light for light slot j: under ``sobol`` the K picks of a
    camera sample are one stratified group (``sampling.rng.group_slot``), under ``independent`` the first slot of
    j's ``n_per_light`` takes it."""
    if strategy == MIS:
        return group_slot(state, n_bsdf, (m - n_bsdf) // n_per_light, (j - n_bsdf) // n_per_light, n_per_light)
    return group_slot(state, 0, m, j)


@jit
def _pick_number(state, n_bsdf, n_per_light, m, strategy, j, u0):
    """The number that picks the light for light slot j whose 2D pair begins with u0.  With one sample per picked
    light, u0 itself (Mitsuba 3's ``sample_reuse``): the selector hands back what is left of it to sample the light,
    so the samples that go to one light keep the pair's stratification; a separate number (the layout's 1D choice of
    ``_pick_slot``) left each light a random subset of the net (decisions.md 74: relMSE 5.99e-4 -> 5.90e-4 on
    the area scene).
    With ``n_per_light`` > 1 the group's slots share one pick, which their pairs cannot all make: the 1D number."""
    if n_per_light == 1:
        return u0
    rp, picker = _pick_slot(state, n_bsdf, n_per_light, m, strategy, j)
    return uniform(rp, 4 + 3 * picker)


@jit_parallel
def _lights_setup(
    s,
    env,
    compensate,
    has_env,
    lights,
    sel,
    cam,
    sampler,
    seed,
    pixels,
    spp_pass,
    sample_start,
    dirs,
    t,
    kind,
    index,
    prim,
    b1,
    b2,
    strategy,
    light_strategy,
    n_bsdf,
    n_light,
    n_per_light,
    direct,
    point,
    gnormal,
    point_error,
    frame,
    wo_local,
    material,
    state,
    wdir,
    wloc,
    tpdf,
    bweight,
    radiance,
    seg,
    slot_light,
    ray_o,
    hit_t,
    hit_kind,
    hit_index,
    hit_prim,
    hit_b1,
    hit_b2,
    hit_mesh,
    counter,
    workers,
):
    m = n_bsdf + n_light
    ox, oy, oz = cam[0], cam[1], cam[2]
    n_work = dirs.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for k in range(lo, hi):
                base = k * m
                material[k] = -1
                for j in range(m):
                    state[base + j] = SLOT_NONE
                    hit_mesh[base + j] = False
                dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
                if kind[k] == MISS:
                    if has_env:
                        direct[k, 0], direct[k, 1], direct[k, 2] = env_eval(env, dx, dy, dz)
                    else:
                        direct[k, 0] = direct[k, 1] = direct[k, 2] = 0.0
                    continue
                hit = (kind[k], index[k], prim[k], b1[k], b2[k], t[k])
                p, ng, err, wo = store_shading_frame(
                    s, k, hit, ox, oy, oz, dx, dy, dz, point, gnormal, point_error, frame, wo_local, material
                )
                direct[k, 0], direct[k, 1], direct[k, 2] = _emitted(s, lights, hit, p, dx, dy, dz)
                if wo[2] <= 0.0:
                    continue
                ts, tt, ns, wo = load_shading_frame(frame, wo_local, k)
                mk, mp = s.material_kind[material[k]], s.material_params[material[k]]
                rs = sample_state(sampler, seed, pixels[k // spp_pass], sample_start + k % spp_pass)
                for j in range(m):
                    r = base + j
                    rj, slot = technique_slot(rs, strategy, n_bsdf, m - n_bsdf, j)
                    u0, u1 = uniform_2d(rj, 2 + 3 * slot)
                    technique = strategy
                    if strategy == MIS:
                        technique = BRDF if j < n_bsdf else ENV
                    if technique == ENV:
                        light, pmf, u_rest = select_light(
                            sel,
                            p[0],
                            p[1],
                            p[2],
                            ng[0],
                            ng[1],
                            ng[2],
                            _pick_number(rs, n_bsdf, n_per_light, m, strategy, j, u0),
                        )
                        if light < 0 or pmf <= 0.0:
                            continue
                        if n_per_light == 1:
                            u0 = u_rest  # the pair's first number picked the light: what is left of it samples it
                        if light == sel.env_index:
                            wx, wy, wz, pdf = env_sample(env, compensate[material[k]], u0, u1)
                            lr, lg, lb = env_eval(env, wx, wy, wz)
                            dist = math.inf
                        else:
                            wx, wy, wz, dist, lr, lg, lb, pdf = light_sample(
                                lights, light, light_strategy, p[0], p[1], p[2], ng[0], ng[1], ng[2], u0, u1
                            )
                        if pdf <= 0.0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
                            continue
                        wdir[r, 0], wdir[r, 1], wdir[r, 2] = wx, wy, wz
                        radiance[r, 0], radiance[r, 1], radiance[r, 2] = lr, lg, lb
                        tpdf[r] = pmf * pdf
                        seg[r] = dist
                        slot_light[r] = light
                        state[r] = SLOT_LIGHT
                        continue
                    st, wi, pdf, w = sample_direction(technique, mk, mp, wo, u0, u1, uniform(rj, 4 + 3 * slot))
                    if st == SLOT_NONE:
                        continue
                    if st == SLOT_BSDF:
                        bweight[r, 0], bweight[r, 1], bweight[r, 2] = w
                    state[r] = st
                    wx, wy, wz = to_world(ts, tt, ns, wi[0], wi[1], wi[2])
                    wdir[r, 0], wdir[r, 1], wdir[r, 2] = wx, wy, wz
                    wloc[r, 0], wloc[r, 1], wloc[r, 2] = wi
                    tpdf[r] = pdf
                    # the nearest hit along the direction decides what it sees (an emitter, the sky, or nothing)
                    qx, qy, qz = ray_offset(p[0], p[1], p[2], ng[0], ng[1], ng[2], err, wx, wy, wz)
                    ray_o[r, 0], ray_o[r, 1], ray_o[r, 2] = qx, qy, qz
                    th, kh, ih = closest_analytic(s, qx, qy, qz, wx, wy, wz, np.inf)
                    hit_t[r], hit_kind[r], hit_index[r] = th, kh, ih
                    hit_prim[r] = 0
                    hit_b1[r] = 0.0
                    hit_b2[r] = 0.0
                    hit_mesh[r] = may_hit_mesh(s, qx, qy, qz, wx, wy, wz, th)
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _lights_finish(
    s,
    env,
    compensate,
    has_env,
    lights,
    sel,
    strategy,
    light_strategy,
    n_bsdf,
    n_light,
    beta,
    point,
    gnormal,
    point_error,
    frame,
    wo_local,
    material,
    state,
    wdir,
    wloc,
    tpdf,
    bweight,
    radiance,
    seg,
    slot_light,
    ray_o,
    hit_t,
    hit_kind,
    hit_index,
    hit_prim,
    hit_b1,
    hit_b2,
    contrib,
    flags,
    shadow_o,
    shadow_d,
    shadow_t,
    counter,
    workers,
):
    m = n_bsdf + n_light
    inv_m = 1.0 / m
    n_work = point.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for k in range(lo, hi):
                base = k * m
                for j in range(m):
                    flags[base + j] = NONE
                if material[k] < 0:
                    continue
                ts, tt, ns, wo = load_shading_frame(frame, wo_local, k)
                mk, mp = s.material_kind[material[k]], s.material_params[material[k]]
                px, py, pz = point[k, 0], point[k, 1], point[k, 2]
                nx, ny, nz = gnormal[k, 0], gnormal[k, 1], gnormal[k, 2]
                err = point_error[k]
                for j in range(m):
                    r = base + j
                    st = state[r]
                    if st == SLOT_NONE:
                        continue
                    wx, wy, wz = wdir[r, 0], wdir[r, 1], wdir[r, 2]
                    if st == SLOT_LIGHT:
                        wi = to_local(ts, tt, ns, wx, wy, wz)
                        f = bsdf_eval(mk, mp, wo, wi)
                        if f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0:
                            continue
                        if strategy != MIS:
                            scale = wi[2] / tpdf[r] * inv_m
                        else:  # one division for the weight and the density (sampling/mis.py, decisions.md 63)
                            # no BSDF direction meets a point or spot light: density 0, weight 1
                            pb = 0.0 if is_delta(lights, slot_light[r]) else bsdf_pdf(mk, mp, wo, wi)
                            scale = wi[2] * mis_weight_over(n_light, tpdf[r], n_bsdf, pb, beta)
                        cr, cg, cb = (
                            f[0] * radiance[r, 0] * scale,
                            f[1] * radiance[r, 1] * scale,
                            f[2] * radiance[r, 2] * scale,
                        )
                        if cr == 0.0 and cg == 0.0 and cb == 0.0:
                            continue
                        qx, qy, qz = ray_offset(px, py, pz, nx, ny, nz, err, wx, wy, wz)
                        tmax = math.inf
                        if seg[r] < math.inf:
                            # a point x on an area light: the shadow ray leaves the offset origin aimed at x moved
                            # toward p by x's own error bound, and ends there (pbrt-v4's SpawnRayTo offsets both
                            # ends; from the offset origin along the original direction, a grazing ray would meet
                            # the light's plane before the segment ends and shadow itself)
                            qx, qy, qz, wx, wy, wz, tmax = _ray_to_light(
                                lights, slot_light[r], px, py, pz, qx, qy, qz, wx, wy, wz, seg[r]
                            )
                        if occluded_analytic(s, qx, qy, qz, wx, wy, wz, tmax):
                            flags[r] = BLOCKED
                            continue
                        contrib[r, 0], contrib[r, 1], contrib[r, 2] = cr, cg, cb
                        if may_hit_mesh(s, qx, qy, qz, wx, wy, wz, tmax):
                            flags[r] = TEST_MESH
                            shadow_o[r, 0], shadow_o[r, 1], shadow_o[r, 2] = qx, qy, qz
                            shadow_d[r, 0], shadow_d[r, 1], shadow_d[r, 2] = wx, wy, wz
                            shadow_t[r] = tmax if tmax < MESH_FAR else MESH_FAR
                        else:
                            flags[r] = VISIBLE
                        continue
                    # a BSDF or hemisphere direction: what does it hit?
                    light = -1
                    lr = lg = lb = 0.0
                    p_light = 0.0
                    if hit_kind[r] == MISS:
                        if has_env:
                            (lr, lg, lb), penv = env_eval_pdf(env, compensate[material[k]], wx, wy, wz)
                            light = sel.env_index
                            p_light = penv
                    else:
                        light = emitter_of(s, hit_kind[r], hit_index[r], hit_prim[r])
                        if light >= 0:
                            # the emitter's radiance and light density at the point this ray hit (Mitsuba 3's
                            # direct: pdf_emitter_direction(si, ds) with ds from the BSDF ray's own hit)
                            hit = surface(
                                s,
                                hit_kind[r],
                                hit_index[r],
                                hit_prim[r],
                                hit_b1[r],
                                hit_b2[r],
                                ray_o[r, 0],
                                ray_o[r, 1],
                                ray_o[r, 2],
                                wx,
                                wy,
                                wz,
                                hit_t[r],
                            )
                            x = hit[0]
                            ln = light_normal(lights, light, x[0], x[1], x[2])
                            lr, lg, lb = light_radiance(lights, light, -(ln[0] * wx + ln[1] * wy + ln[2] * wz))
                            p_light = light_pdf_at(
                                lights, light, light_strategy, px, py, pz, nx, ny, nz, x[0], x[1], x[2]
                            )
                    if light < 0 or (lr == 0.0 and lg == 0.0 and lb == 0.0):
                        continue
                    if st == SLOT_BSDF:
                        scale = inv_m
                        if strategy == MIS:
                            pl = selector_pmf(sel, px, py, pz, nx, ny, nz, light) * p_light
                            scale = mis_weight_share(n_bsdf, tpdf[r], n_light, pl, beta)
                        cr, cg, cb = bweight[r, 0] * lr * scale, bweight[r, 1] * lg * scale, bweight[r, 2] * lb * scale
                    else:
                        wi = (wloc[r, 0], wloc[r, 1], wloc[r, 2])
                        f = bsdf_eval(mk, mp, wo, wi)
                        scale = wi[2] / tpdf[r] * inv_m
                        cr, cg, cb = f[0] * lr * scale, f[1] * lg * scale, f[2] * lb * scale
                    if cr == 0.0 and cg == 0.0 and cb == 0.0:
                        continue
                    contrib[r, 0], contrib[r, 1], contrib[r, 2] = cr, cg, cb
                    flags[r] = VISIBLE  # the closest hit already decided visibility
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _lights_mesh_hits(
    mesh_scene,
    scratch,
    ray_counts,
    todo,
    wdir,
    ray_o,
    hit_t,
    hit_kind,
    hit_index,
    hit_prim,
    hit_b1,
    hit_b2,
    counter,
    workers,
):
    """The slots in ``todo`` (BSDF and hemisphere directions flagged in ``hit_mesh``): the nearest mesh hit, where
    it is nearer than the analytic one."""
    n_work = todo.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for q in range(lo, hi):
                r = todo[q]
                ray_counts[numba.get_thread_id(), 2] += 1
                far = hit_t[r] if hit_t[r] < np.inf else MESH_FAR
                mt, mesh, face, mb1, mb2 = closest_mesh_hit(
                    mesh_scene, scratch, ray_o[r, 0], ray_o[r, 1], ray_o[r, 2], wdir[r, 0], wdir[r, 1], wdir[r, 2], far
                )
                if mesh >= 0:
                    hit_t[r], hit_kind[r], hit_index[r], hit_prim[r], hit_b1[r], hit_b2[r] = (
                        mt,
                        MESH,
                        mesh,
                        face,
                        mb1,
                        mb2,
                    )
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _lights_mesh_shadows(mesh_scene, scratch, ray_counts, todo, shadow_o, shadow_d, shadow_t, flags, counter, workers):
    """The slots in ``todo`` (shadow rays flagged TEST_MESH), over their segments (0, shadow_t), through Embree:
    each becomes VISIBLE or BLOCKED."""
    n_work = todo.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for q in range(lo, hi):
                r = todo[q]
                ray_counts[numba.get_thread_id(), 1] += 1
                blocked = mesh_occluded(
                    mesh_scene,
                    scratch,
                    shadow_o[r, 0],
                    shadow_o[r, 1],
                    shadow_o[r, 2],
                    shadow_d[r, 0],
                    shadow_d[r, 1],
                    shadow_d[r, 2],
                    shadow_t[r],
                )
                flags[r] = BLOCKED if blocked else VISIBLE
            lo, hi = claim_range(counter, n_work)


#: the slots each Embree stage traces, gathered from the pass buffers before it runs (wavefront.render passes them
#: as ``todo``)
WORKLISTS = {
    _lights_mesh_hits: lambda b: np.flatnonzero(b["hit_mesh"]),
    _lights_mesh_shadows: lambda b: np.flatnonzero(b["flags"] == TEST_MESH),
}


def slot_buffers(nm: int) -> dict[str, np.ndarray]:
    """The extra per-slot arrays of this path, keyed by kernel parameter name."""
    return {
        "seg": fresh_array(nm),  # distance to the sampled point on an area light (inf: the environment)
        "slot_light": fresh_array(nm, np.int64),  # the light a light sample went to
        "ray_o": fresh_array((nm, 3)),  # origin of a BSDF direction's ray (offset from the surface)
        "hit_t": fresh_array(nm),  # its nearest hit
        "hit_kind": fresh_array(nm, np.int64),
        "hit_index": fresh_array(nm, np.int64),
        "hit_prim": fresh_array(nm, np.int64),
        "hit_b1": fresh_array(nm),
        "hit_b2": fresh_array(nm),
        "hit_mesh": fresh_array(nm, np.bool_),  # a mesh may be nearer than the analytic hit
        # shadow rays left for Embree, in float32 as Embree stores them
        "shadow_o": fresh_array((nm, 3), np.float32),
        "shadow_d": fresh_array((nm, 3), np.float32),
        "shadow_t": fresh_array(nm, np.float32),  # the segment's length
    }


def stages(with_meshes: bool) -> tuple:
    """The kernels of one pass, in order (the Embree stages only for scenes with meshes)."""
    if with_meshes:
        return _lights_setup, _lights_mesh_hits, _lights_finish, _lights_mesh_shadows
    return _lights_setup, _lights_finish
