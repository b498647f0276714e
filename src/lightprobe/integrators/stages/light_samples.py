"""Stage 3, light samples: each light slot picks a light and samples a direction toward it.

``light_samples`` is the stage of every scene: the selector (``emitters/selection.py``) picks a row of the light
table with the first number of the slot's 2D pair (what is left of that number, and the pair's second, sample the
light: decisions.md 74), and the light contract (``emitters/lights.py``) samples it.  The slot keeps the direction,
the radiance arriving, the density (the light's x its selection probability: the lecture's p_l p(x')), the
distance to the sampled point and which light it was.

Where the environment map is the scene's only light, the pick is certain and the samples are the map's alone: three
specialisations of this stage sample it without a selector and leave the radiance lookups to their own stage
(``radiance.py``), where they run 8 at a time (decisions.md 41-47):

``environment_lanes``
    8 samples of the bilinear density at a time, in vector IR (``environment_lanes.env_sample_block``);
``environment_scalar``
    one at a time, for the other densities (``exact``, ``pbrt``) and small maps;
``environment_resampled``
    resampled importance sampling from ``env_candidates`` candidates (``--env-candidates``, decisions.md 24).

Those drop a sample whose direction lies below the shading normal (the BSDF would give it nothing) before any
lookup is made; the general stage leaves that to the finish stage's BSDF evaluation.
"""

from __future__ import annotations

import math

from ..._numba import jit_body
from ...bsdfs.dispatch import bsdf_eval
from ...emitters.envmap import env_lookup, env_sample_coords, env_sample_full
from ...emitters.lights import light_sample_of
from ...emitters.selection import no_receiver_terms, receiver_terms, select_light_at
from ...geometry.frame import to_local
from ...sampling.rng import sample_state, uniform, uniform_2d
from ...simd import LANES
from ..techniques import ENV, MIS, SLOT_LIGHT, SLOT_NONE, load_shading_frame, pick_number, technique_slot
from ..textured_hits import material_parameters
from .environment_lanes import env_sample_block

__all__ = [
    "environment_blocks",
    "environment_lanes",
    "environment_resampled",
    "environment_scalar",
    "light_samples",
    "slots_of_pass",
]


def slots_of_pass(c, cams, slots):
    """Items of the stages that go slot by slot: every slot of the pass."""
    return slots.state.shape[0]


@jit_body
def light_samples(env, lights, sel, c, cams, slots, lo, hi):
    """Slots lo .. hi - 1: a light and a direction toward it for each light slot."""
    m = c.m
    if slots.light.shape[0] == 0:  # never without its record of the picks (pass_state.py)
        return
    learning = slots.learn.shape[0] > 0
    # what the K picks of one camera sample share (the root's importances, the learned cell), once per sample
    last = -1
    terms = no_receiver_terms()
    for r in range(lo, hi):
        if learning:
            slots.learn[r] = -1.0  # not a light sample, unless a light is picked below
        if slots.state[r] != SLOT_LIGHT:
            continue
        k = r // m
        px, py, pz = cams.point[k, 0], cams.point[k, 1], cams.point[k, 2]
        nx, ny, nz = cams.gnormal[k, 0], cams.gnormal[k, 1], cams.gnormal[k, 2]
        u0, u1 = slots.u[r, 0], slots.u[r, 1]
        if c.n_per_light == 1:
            u_pick = u0  # the pair's first number picks the light: what is left of it samples it
        else:
            rs = sample_state(c.sampler, c.seed, c.pixels[k // c.spp_pass], c.sample_start + k % c.spp_pass)
            u_pick = pick_number(rs, c.n_bsdf, c.n_per_light, m, c.strategy, r % m, u0)
        compensated = c.compensate[cams.material[k]]
        if k != last:
            terms = receiver_terms(sel, px, py, pz, nx, ny, nz, compensated)
            last = k
        light, pmf, u_rest = select_light_at(sel, terms, px, py, pz, nx, ny, nz, u_pick, compensated)
        if light < 0 or pmf <= 0.0:
            slots.state[r] = SLOT_NONE
            continue
        if learning:  # a sample of this light, whatever it gives (finish.py: its value)
            slots.learn[r] = pmf
            slots.light[r] = light
        if c.n_per_light == 1:
            u0 = u_rest
        ls = light_sample_of(lights, env, light, c.light_strategy, compensated, px, py, pz, nx, ny, nz, u0, u1)
        if ls.pdf <= 0.0 or (ls.r == 0.0 and ls.g == 0.0 and ls.b == 0.0):
            slots.state[r] = SLOT_NONE
            if learning:  # a sample that gives nothing (a light facing away), not one a shadow blocked
                slots.learn[r] = 0.0
            continue
        slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2] = ls.wx, ls.wy, ls.wz
        slots.radiance[r, 0], slots.radiance[r, 1], slots.radiance[r, 2] = ls.r, ls.g, ls.b
        slots.tpdf[r] = pmf * ls.pdf
        slots.light[r] = light
        if slots.seg.shape[0] > 0:  # bounded lights: the shadow ray ends at the sampled point
            slots.seg[r] = ls.distance


def environment_blocks(c, cams, slots):
    """Items of ``environment_lanes``: blocks of 8 light slots, numbered over the pass's camera samples (under MIS
    a camera sample's light slots are its last m - n_bsdf, under ``env`` all m, and the other strategies have
    none)."""
    first = c.n_bsdf if c.strategy == MIS else 0
    count = c.m - first if c.strategy == MIS or c.strategy == ENV else 0
    return (cams.t.shape[0] * count + LANES - 1) // LANES


@jit_body
def environment_lanes(env, c, cams, slots, lo, hi):
    """Blocks lo .. hi - 1 of 8 environment samples (the bilinear density, emitters/envmap_bilinear.py)."""
    first = c.n_bsdf if c.strategy == MIS else 0
    count = c.m - first if c.strategy == MIS or c.strategy == ENV else 0
    for block in range(lo, hi):
        env_sample_block(
            slots.u, slots.state, cams.material, c.compensate, c.m, cams.frame, env.luminance, env.node_sines,
            env.conditional_cdf, env.marginal_cdf, env.comp_conditional_cdf, env.comp_marginal_cdf, env.row_guide,
            env.marginal_guide, env.comp_row_guide, env.comp_marginal_guide, env.comp_offset, env.row_angles,
            env.column_angles, env.to_world, slots.wdir, slots.tpdf, slots.uv, first, count, block * LANES,
        )  # fmt: skip


@jit_body
def environment_scalar(env, c, cams, slots, lo, hi):
    """Slots lo .. hi - 1: directions, densities and lat-long coordinates of environment samples; those below the
    surface are dropped."""
    m = c.m
    for r in range(lo, hi):
        if slots.state[r] != SLOT_LIGHT:
            continue
        k = r // m
        wx, wy, wz, pdf, u, y, cos_theta = env_sample_full(
            env, c.compensate[cams.material[k]], slots.u[r, 0], slots.u[r, 1]
        )
        if cams.frame[k, 6] * wx + cams.frame[k, 7] * wy + cams.frame[k, 8] * wz <= 0.0 or pdf <= 0.0:
            slots.state[r] = SLOT_NONE
            continue
        slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2] = wx, wy, wz
        slots.tpdf[r] = pdf
        slots.uv[r, 0] = u
        slots.uv[r, 1] = env_sample_coords(env, y, cos_theta)


@jit_body
def environment_resampled(s, env, c, cams, slots, lo, hi):
    """Environment samples by resampled importance sampling (Talbot, Cline and Egbert 2005): M candidates x_i from
    the environment's PDF p, one kept with probability proportional to w_i = p^(x_i) / p(x_i), where the target
    p^ = luminance(f L) cos is the product the light sample estimates (map x BSDF x cosine, without visibility).
    The kept y is weighted by W = (1/M) sum w_i / p^(y), unbiased wherever p^ > 0 covers f L cos (it does: the
    luminance weights are positive).  ``tpdf`` gets the effective density 1 / W, ``light_pdf`` the source density
    p(y) for the MIS weights: weights from p and the BSDF's pdf still sum to one at every direction, which is all
    MIS needs to stay unbiased (Veach 1997, 9.2).  Candidate i > 0 of slot j takes the random numbers of virtual
    slot 64 + j M + i (past every real slot); the choice uses each candidate's third number (weighted reservoir
    sampling), so the kept sample is a pure function of the sample's coordinates."""
    m = c.m
    n_candidates = c.env_candidates
    for r in range(lo, hi):
        if slots.state[r] != SLOT_LIGHT:
            continue
        k = r // m
        j = r % m
        rs = sample_state(c.sampler, c.seed, c.pixels[k // c.spp_pass], c.sample_start + k % c.spp_pass)
        ts, tt, ns, wo = load_shading_frame(cams.frame, cams.wo_local, k)
        mk, mp = s.material_kind[cams.material[k]], material_parameters(s, cams, k)
        compensated = c.compensate[cams.material[k]]
        wsum = 0.0
        kept_target = 0.0
        kept = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # direction, source pdf, u, v
        for i in range(n_candidates):
            if i == 0:
                rj, slot = technique_slot(rs, c.strategy, c.n_bsdf, m - c.n_bsdf, j)
                u0, u1, uc = slots.u[r, 0], slots.u[r, 1], uniform(rj, 4 + 3 * slot)
            else:
                v = 64 + j * n_candidates + i
                (u0, u1), uc = uniform_2d(rs, 2 + 3 * v), uniform(rs, 4 + 3 * v)
            wx, wy, wz, pdf, u, y, cos_theta = env_sample_full(env, compensated, u0, u1)
            if pdf <= 0.0:
                continue
            wi = to_local(ts, tt, ns, wx, wy, wz)
            if wi[2] <= 0.0:
                continue
            f = bsdf_eval(mk, mp, wo, wi)
            vv = env_sample_coords(env, y, cos_theta)
            lr, lg, lb = env_lookup(env, u, vv)
            target = (0.212671 * f[0] * lr + 0.715160 * f[1] * lg + 0.072169 * f[2] * lb) * wi[2]
            if not target > 0.0:
                continue
            w = target / pdf
            wsum += w
            if uc * wsum < w:  # keep candidate i with probability w_i / (w_0 + ... + w_i)
                kept_target = target
                kept = (wx, wy, wz, pdf, u, vv)
        if wsum <= 0.0 or not math.isfinite(wsum):
            slots.state[r] = SLOT_NONE
            continue
        slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2] = kept[0], kept[1], kept[2]
        slots.tpdf[r] = kept_target * n_candidates / wsum
        slots.light_pdf[r] = kept[3]
        slots.uv[r, 0] = kept[4]
        slots.uv[r, 1] = kept[5]
