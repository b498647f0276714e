"""Stage 5, finish: each live slot's unoccluded contribution, with its MIS weight, and what its shadow ray must do.

The estimator of one camera sample (the lecture's, with Veach's multi-sample MIS):

    L_direct = sum over BSDF slots of f cos / p_bsdf * L * w_bsdf / n_bsdf
             + sum over light slots of f cos / (p_l p_li) * L * w_light / (K N)

with w the balance or power heuristic on sample-count-weighted densities (``techniques.bsdf_share`` and
``techniques.light_scale``, after ``sampling/mis.py``); a delta light's sample takes weight 1 (no BSDF direction
meets it).  A single technique divides by m instead.  A BSDF slot's weight was applied by the BSDF-ray stage where
it found the light a ray meets (``c.bsdf_weighed``: every scene but those lit by the environment map alone).

Shadow rays: every light sample's, and a BSDF ray's where the scene has no emissive surface (it reaches the infinite
lights only if nothing blocks it) are flagged ``TEST_ANALYTIC`` for the shadow stages; a BSDF ray that found its
nearest hit needs none (``VISIBLE``).
"""

from __future__ import annotations

from ..._numba import jit_body
from ...bsdfs.dispatch import bsdf_eval, bsdf_pdf
from ...emitters.lights import is_delta
from ...geometry.frame import to_local
from ..techniques import (
    MIS,
    NONE,
    SLOT_BSDF,
    SLOT_LIGHT,
    SLOT_NONE,
    TEST_ANALYTIC,
    VISIBLE,
    bsdf_share,
    light_scale,
    load_shading_frame,
)
from ..textured_hits import material_parameters

__all__ = ["finish"]


@jit_body
def finish(s, lights, c, cams, slots, lo, hi):
    """Camera samples lo .. hi - 1."""
    m = c.m
    bsdf_rays_hit = slots.hit_t.shape[0] > 0  # BSDF rays found their nearest hit: nothing left to test
    picked = slots.light.shape[0] > 0  # light slots picked their light (the environment alone has no record)
    resampled = c.env_candidates > 1
    mis = c.strategy == MIS
    flags, contrib = slots.flags, slots.contrib
    for k in range(lo, hi):
        base = k * m
        for j in range(m):
            flags[base + j] = NONE
        if cams.material[k] < 0:
            continue
        ts, tt, ns, wo = load_shading_frame(cams.frame, cams.wo_local, k)
        mk, mp = s.material_kind[cams.material[k]], material_parameters(s, cams, k)
        for j in range(m):
            r = base + j
            st = slots.state[r]
            if st == SLOT_NONE:
                continue
            wx, wy, wz = slots.wdir[r, 0], slots.wdir[r, 1], slots.wdir[r, 2]
            lr, lg, lb = slots.radiance[r, 0], slots.radiance[r, 1], slots.radiance[r, 2]
            if st == SLOT_BSDF:
                scale = 1.0 if c.bsdf_weighed else bsdf_share(c, slots.tpdf[r], slots.light_pdf[r])
                cr = slots.bweight[r, 0] * lr * scale
                cg = slots.bweight[r, 1] * lg * scale
                cb = slots.bweight[r, 2] * lb * scale
            else:
                if st == SLOT_LIGHT:
                    wi = to_local(ts, tt, ns, wx, wy, wz)
                else:
                    wi = (slots.wloc[r, 0], slots.wloc[r, 1], slots.wloc[r, 2])
                f = bsdf_eval(mk, mp, wo, wi)
                if st == SLOT_LIGHT and slots.learn.shape[0] > 0:
                    # for the selection's learning: lum(f L cos) / the light's density, its pick's taken out
                    lum = 0.212671 * f[0] * lr + 0.715160 * f[1] * lg + 0.072169 * f[2] * lb
                    slots.learn[r] = max(0.0, lum) * max(0.0, wi[2]) / slots.tpdf[r] * slots.learn[r]
                if f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0:
                    continue
                if st == SLOT_LIGHT:
                    pb = 0.0
                    # no BSDF direction meets a delta light: density 0, weight 1
                    if mis and not (picked and is_delta(lights, slots.light[r])):
                        pb = bsdf_pdf(mk, mp, wo, wi)
                    p_source = slots.light_pdf[r] if resampled else 0.0
                    scale = light_scale(c, wi[2], slots.tpdf[r], pb, p_source)
                else:  # a hemisphere sample
                    scale = wi[2] / slots.tpdf[r] * (1.0 if c.bsdf_weighed else 1.0 / m)
                cr, cg, cb = f[0] * lr * scale, f[1] * lg * scale, f[2] * lb * scale
            if cr == 0.0 and cg == 0.0 and cb == 0.0:
                continue
            contrib[r, 0], contrib[r, 1], contrib[r, 2] = cr, cg, cb
            flags[r] = VISIBLE if bsdf_rays_hit and st != SLOT_LIGHT else TEST_ANALYTIC
