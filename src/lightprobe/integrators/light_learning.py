"""The render's side of learned light selection (``light_sampler = "learned"``; emitters/selection_learning.py):
which renders learn, the pilot's light samples kept as records, and the selector learned from them.

A render learns from its pilot: the adaptive pilot, or, in a uniform render from sample 0, its first
``adaptive.pilot_spp(spp)`` samples per pixel (the rounds split there).  Every sample after the pilot uses what was
learned; the pilot's own samples use the BVH, so the image is a pure function of (seed, settings).  A render that
starts past sample 0 (a sample range, a resumed render) has no pilot to learn from and uses the BVH throughout.
"""

from __future__ import annotations

from .._numba import jit_parallel, prange
from ..emitters.selection import LightSelector
from ..emitters.selection_learning import Records, learned, with_cut
from .techniques import ENV, MIS, VISIBLE

__all__ = ["Learning", "learns"]


def learns(selector: LightSelector, strategy: str, light_sampler: str, first_sample: int, spp: int) -> bool:
    """Whether a render learns its light selection: ``learned`` asked for, light samples taken (``mis`` or
    ``env``), at least two bounded lights in a BVH, a pilot of at least one sample, and the render starting at
    sample 0."""
    return (
        light_sampler == "learned"
        and strategy in ("mis", "env")
        and selector.n_bounded >= 2
        and selector.wide_child.shape[0] > 0
        and first_sample == 0
        and spp >= 4
    )


class Learning:
    """One render's learning: the selector with its clusters (as the BVH until :meth:`learn`), the records of the
    pilot's light samples, and the learned selector."""

    def __init__(self, selector: LightSelector, pixels: int, pilot: int, strategy: int, n_bsdf: int, m: int):
        self.selector = with_cut(selector)
        self.first = n_bsdf if strategy == MIS else 0  # a camera sample's first light slot
        self.slots = m - self.first if strategy in (MIS, ENV) else 0
        self.records = Records(pixels, pilot, self.slots)
        self.recording = True

    def record(self, records: tuple) -> None:
        """Keep the light samples of the pass whose stage records are ``records`` (``_Pass.records``)."""
        _s, _env, _lights, sel, c, cams, slots, _acc = records
        if not self.recording or c.sample_start >= self.records.samples:
            return
        r = self.records
        _record(sel, c, cams, slots, self.first, self.slots, r.samples, r.stride, r.point, r.normal, r.light, r.value)

    def learn(self) -> LightSelector:
        """The selector learned from the records (kept no longer)."""
        self.selector = learned(self.selector, self.records)
        self.recording = False
        self.records = None
        return self.selector

    def stats(self) -> dict:
        sel = self.selector
        return {
            "learned_levels": int(sel.cut_levels),
            "learned_cells": int((sel.cell_next[sel.cell_axis < 0, 0] >= 0).sum()) if sel.cell_axis.size else 0,
        }


@jit_parallel
def _record(sel, c, cams, slots, first, n_light, samples, stride, point, normal, light, value):
    """Each light slot of the pass's first ``samples`` samples of every ``stride``-th pixel: its shading point and
    normal, its light, and lum(f L cos V) / the density of the light's point (0 if the shadow ray was blocked)."""
    m = c.m
    for k in prange(cams.t.shape[0]):
        sample = c.sample_start + k % c.spp_pass
        pixel = c.pixels[k // c.spp_pass]
        if sample >= samples or pixel % stride != 0:
            continue
        base = ((pixel // stride) * samples + sample) * n_light
        shaded = cams.material[k] >= 0
        for j in range(n_light):
            r = k * m + first + j
            rec = base + j
            if not shaded or slots.learn[r] < 0.0 or slots.light[r] >= sel.n_bounded:
                light[rec] = -1
                continue
            for a in range(3):
                point[rec, a] = cams.point[k, a]
                normal[rec, a] = cams.gnormal[k, a]
            light[rec] = slots.light[r]
            value[rec] = slots.learn[r] if slots.flags[r] == VISIBLE else 0.0
