"""Stage 2, shading setup: each camera sample's hit point, shading frame and material, what its camera ray sees
directly, and its shading slots' directions.

A camera ray that misses sees the infinite lights (the environment, directional lights' discs); one that hits an
emitter sees its radiance (from the hit itself, never a second intersection, which from another origin can miss a
small light's edge).  Then each of the camera sample's ``m`` slots gets its random numbers (under ``sobol`` made for a
run of camera samples, 8 slots at a time in integer lanes, ``sobol_lanes.py``: the same bits as ``uniform_2d`` and
``uniform``) and either a direction from BSDF or hemisphere sampling (state ``SLOT_BSDF`` / ``SLOT_HEMI``, with its
density and, for a BSDF sample, its weight f cos / pdf) or, for a light slot, its 2D pair for the light-sample stage
(``SLOT_LIGHT``).
"""

from __future__ import annotations

import numpy as np
from numba import types
from numba.extending import overload

from ..._numba import jit_body, jit_inline
from ...emitters.lights import emitted, escaped_radiance
from ...geometry.frame import to_world
from ...geometry.intersect import MESH, MISS, RECT, SPHERE
from ...sampling.rng import SOBOL, sample_state, uniform, uniform_2d
from ...simd import LANES
from ..outlines import outline_offset
from ..techniques import (
    BRDF,
    ENV,
    MIS,
    SLOT_BSDF,
    SLOT_LIGHT,
    SLOT_NONE,
    load_shading_frame,
    sample_direction,
    store_shading_frame,
    technique_slot,
)
from ..textured_hits import apply_textures, material_parameters
from .sobol_lanes import slot_numbers_run

__all__ = ["SETUP_RUN", "emitter_of", "shading_setup", "shading_setup_textured"]


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
def _add_outlines(c, cams, k, dx, dy, dz):
    """The outline control variate's G_p - g(x) (integrators/outlines.py), where camera sample k's pixel has one."""
    if c.outline_start.shape[0] == 0:
        return
    pixel = c.pixels[k // c.spp_pass]
    if c.outline_start[pixel] == c.outline_start[pixel + 1]:
        return
    r, g, b = outline_offset(
        c.outline_start, c.outline_shape, c.outline_cover, c.outline_geom, c.outline_radiance, pixel, dx, dy, dz
    )
    cams.direct[k, 0] += r
    cams.direct[k, 1] += g
    cams.direct[k, 2] += b


def _textures_if(textured, s, cams, k, dx, dy, dz):
    """Camera sample k's textures (``textured_hits.apply_textures``) where its material has them, in the stage of a
    scene with textured materials (``textured`` a compile-time True); nothing, and no texture code compiled, in the
    other's (decisions.md 104: the texture lookups were 7 of the demo's 70 s of compiling)."""


@overload(_textures_if, prefer_literal=True)
def _textures_if_overload(textured, s, cams, k, dx, dy, dz):
    if isinstance(textured, types.BooleanLiteral) and textured.literal_value:

        def with_textures(textured, s, cams, k, dx, dy, dz):
            if s.material_textured[cams.material[k]] == 1:
                apply_textures(s, cams, k, dx, dy, dz)

        return with_textures

    def without(textured, s, cams, k, dx, dy, dz):
        pass

    return without


@jit_body
def shading_setup(s, env, lights, c, cams, slots, worker, lo, hi):
    """Camera samples lo .. hi - 1 of a scene without textures."""
    _shading_setup(s, env, lights, c, cams, slots, worker, lo, hi, False)


@jit_body
def shading_setup_textured(s, env, lights, c, cams, slots, worker, lo, hi):
    """Camera samples lo .. hi - 1 of a scene with textured materials."""
    _shading_setup(s, env, lights, c, cams, slots, worker, lo, hi, True)


#: camera samples whose slots' Sobol' numbers are made together (``slot_numbers_run``: 8 slots at a time, across
#: camera samples): the per-thread rows of ``PassConstants.numbers`` hold SETUP_RUN x m of them
SETUP_RUN = 32


@jit_inline
def _shading_setup(s, env, lights, c, cams, slots, worker, lo, hi, textured):
    """Camera samples lo .. hi - 1 (``textured``: a compile-time constant, whether their materials may be), in runs
    of SETUP_RUN: each sample's hit, frame and what its ray sees; then, under ``sobol``, the run's slot numbers 8 at a
    time; then each shaded sample's slots."""
    for k0 in range(lo, hi, SETUP_RUN):
        k1 = min(hi, k0 + SETUP_RUN)
        _hits(s, env, lights, c, cams, slots, k0, k1, textured)
        if c.sampler == SOBOL:
            own = c.numbers[worker]
            for f in range(0, (k1 - k0) * c.m, LANES):
                slot_numbers_run(
                    own, c.seed, c.pixels, c.spp_pass, c.sample_start, cams.material, c.strategy == MIS, c.n_bsdf, c.m,
                    k0, k1 - k0, f,
                )  # fmt: skip
        _slots(s, c, cams, slots, worker, k0, k1)


@jit_inline
def _hits(s, env, lights, c, cams, slots, k0, k1, textured):
    """Camera samples k0 .. k1 - 1: the hit point, shading frame and material (``material`` -1 where nothing is
    shaded), the radiance the camera ray sees directly, the textures; every slot emptied."""
    m = c.m
    ox, oy, oz = c.cam[0], c.cam[1], c.cam[2]
    state = slots.state
    for k in range(k0, k1):
        base = k * m
        cams.material[k] = -1  # no shading for this camera sample (a miss, or the back of a one-sided surface)
        for j in range(m):
            state[base + j] = SLOT_NONE
        dx, dy, dz = cams.dirs[k, 0], cams.dirs[k, 1], cams.dirs[k, 2]
        if cams.kind[k] == MISS:
            cams.direct[k, 0], cams.direct[k, 1], cams.direct[k, 2] = escaped_radiance(lights, env, dx, dy, dz)
            _add_outlines(c, cams, k, dx, dy, dz)
            continue
        hit = (cams.kind[k], cams.index[k], cams.prim[k], cams.b1[k], cams.b2[k], cams.t[k])
        p, _, _, wo = store_shading_frame(
            s, k, hit, ox, oy, oz, dx, dy, dz, cams.point, cams.gnormal, cams.point_error, cams.frame, cams.wo_local,
            cams.material,
        )  # fmt: skip
        light = emitter_of(s, hit[0], hit[1], hit[2])
        if light >= 0:
            cams.direct[k, 0], cams.direct[k, 1], cams.direct[k, 2] = emitted(
                lights, light, p[0], p[1], p[2], dx, dy, dz
            )
        else:
            cams.direct[k, 0] = cams.direct[k, 1] = cams.direct[k, 2] = 0.0
        _add_outlines(c, cams, k, dx, dy, dz)
        if wo[2] <= 0.0:
            continue
        _textures_if(textured, s, cams, k, dx, dy, dz)


@jit_inline
def _slots(s, c, cams, slots, worker, k0, k1):
    """The slots of the shaded camera samples among k0 .. k1 - 1: a direction from BSDF or hemisphere sampling, or
    the 2D pair of a light slot; under ``sobol`` from the run's numbers (``c.numbers[worker]``, row (k - k0) m + j)."""
    m, n_bsdf = c.m, c.n_bsdf
    state, wdir, tpdf = slots.state, slots.wdir, slots.tpdf
    sobol = c.sampler == SOBOL
    own = c.numbers[worker]
    for k in range(k0, k1):
        if cams.material[k] < 0:
            continue
        base = k * m
        row = (k - k0) * m
        ts, tt, ns, wo = load_shading_frame(cams.frame, cams.wo_local, k)
        mk, mp = s.material_kind[cams.material[k]], material_parameters(s, cams, k)
        rs = (c.sampler, np.uint64(0), np.uint64(0), np.int64(0))  # the independent sampler's state, below
        if not sobol:
            rs = sample_state(c.sampler, c.seed, c.pixels[k // c.spp_pass], c.sample_start + k % c.spp_pass)
        for j in range(m):
            r = base + j
            technique = c.strategy
            if c.strategy == MIS:
                technique = BRDF if j < n_bsdf else ENV
            if sobol:
                u0, u1, u2 = own[row + j, 0], own[row + j, 1], own[row + j, 2]
            else:
                rj, slot = technique_slot(rs, c.strategy, n_bsdf, m - n_bsdf, j)
                u0, u1 = uniform_2d(rj, 2 + 3 * slot)
                u2 = -1.0  # drawn below where a technique takes it
            if technique == ENV:
                slots.u[r, 0] = u0
                slots.u[r, 1] = u1
                state[r] = SLOT_LIGHT
                continue
            if not sobol:
                u2 = uniform(rj, 4 + 3 * slot)
            st, wi, pdf, w = sample_direction(technique, mk, mp, wo, u0, u1, u2)
            if st == SLOT_NONE:
                continue
            if st == SLOT_BSDF:
                slots.bweight[r, 0], slots.bweight[r, 1], slots.bweight[r, 2] = w
            state[r] = st
            wx, wy, wz = to_world(ts, tt, ns, wi[0], wi[1], wi[2])
            wdir[r, 0], wdir[r, 1], wdir[r, 2] = wx, wy, wz
            if st != SLOT_BSDF:  # the finish stage weighs a BSDF sample by bweight, the others by wi
                slots.wloc[r, 0], slots.wloc[r, 1], slots.wloc[r, 2] = wi
            tpdf[r] = pdf
