"""The render's side of learned light selection (``light_sampler = "learned"``; emitters/selection_learning.py):
which renders learn, the pilot's light samples kept as records, and the selector learned from them.

A render learns from its pilot (``pilot_for``): the first half of the adaptive pilot (``adaptive.pilot_spp``; its
second half already picks with what was learned), or, in a uniform render from sample 0, its first
``UNIFORM_PILOT`` samples per pixel (the rounds split there), whatever its spp, so that a render continued
from its statistics (``render(..., resume=acc)``, which carry the learned cells: ``Accumulator.learned``) learns
what the render that did not stop learned.  Every sample after the pilot uses what was learned; the pilot's own
samples use the BVH, so the image is a pure function of (seed, settings).  A render that starts past sample 0
without a learned accumulator to continue (a sample range of a distributed render, a render resumed inside the
pilot) has nothing to learn from and picks with the BVH.
"""

from __future__ import annotations

import numpy as np

from .._numba import jit
from .._worksharing import in_threads
from ..emitters.selection import LightSelector
from ..emitters.selection_learning import Records, learned, with_cut
from ..errors import ParameterError
from . import adaptive
from .techniques import ENV, MIS, VISIBLE

__all__ = [
    "TABLE_FIELDS",
    "UNIFORM_PILOT",
    "Learning",
    "cells_learned",
    "first_range",
    "learns",
    "restored",
    "table_of",
]

UNIFORM_PILOT = 4  # a uniform render learns from its first 4 samples per pixel
#: the fields of a learned selector a render's statistics carry (``Accumulator.learned``)
TABLE_FIELDS = ("cut_levels", "learn_offset", "cell_axis", "cell_split", "cell_next", "cell_ratio", "defensive")


def pilot_for(spp: int, adaptive_counts: bool) -> int:
    """The samples per pixel a render learns from: the first half of an adaptive render's pilot (its second half
    and the rounds after it use what was learned), or a uniform render's first ``UNIFORM_PILOT``."""
    return max(1, adaptive.pilot_spp(spp) // 2) if adaptive_counts else UNIFORM_PILOT


def first_range(chunk: int, spp: int) -> int:
    """The samples the first of a uniform render's sample ranges (``chunk`` each from sample 0, ``spp`` in all)
    holds, so that it learns the light selection as one whole render of ``spp`` does: ``chunk``, or the
    ``UNIFORM_PILOT`` samples it learns from and one more (a range of no more than those learns nothing)."""
    return min(spp, max(chunk, UNIFORM_PILOT + 1))


def learns(selector: LightSelector, strategy: str, light_sampler: str) -> bool:
    """Whether a render's light selection can learn: ``learned`` asked for, light samples taken (``mis`` or
    ``env``), and at least two bounded lights in a BVH."""
    return (
        light_sampler == "learned"
        and strategy in ("mis", "env")
        and selector.n_bounded >= 2
        and selector.wide_child.shape[0] > 0
    )


def cells_learned(table: dict) -> int:
    """How many cells of a learned table (:func:`table_of`) learned anything (the others pick with the BVH)."""
    axis, nxt = np.asarray(table["cell_axis"]), np.asarray(table["cell_next"])
    return int((nxt[axis < 0, 0] >= 0).sum()) if axis.size else 0


def table_of(selector: LightSelector) -> dict:
    """What a learned selector learned, as arrays (``Accumulator.learned``), with the tree it was learned on
    (its node count and bounded lights) to check it against when a render continues."""
    table = {name: np.asarray(getattr(selector, name)) for name in TABLE_FIELDS}
    table["tree"] = np.array([selector.wide_child.shape[0], selector.n_bounded], np.int64)
    return table


def restored(selector: LightSelector, table: dict) -> LightSelector:
    """``selector`` with the learned ``table`` (:func:`table_of`) of the render it continues."""
    tree = np.asarray(table["tree"])
    if tree.tolist() != [selector.wide_child.shape[0], selector.n_bounded]:
        raise ParameterError(
            "resume: the statistics carry a learned light selection made for another scene's lights "
            f"({int(tree[1])} bounded lights, {int(tree[0])} tree nodes; this scene: {selector.n_bounded}, "
            f"{selector.wide_child.shape[0]})"
        )
    dtypes = {"learn_offset": np.int64, "cell_axis": np.int64, "cell_next": np.int64}
    values = {name: np.ascontiguousarray(table[name], dtypes.get(name, np.float64)) for name in TABLE_FIELDS[1:-1]}
    return selector._replace(cut_levels=int(table["cut_levels"]), defensive=float(table["defensive"]), **values)


class Learning:
    """One render's learning: the selector with its cut (picking as the BVH until :meth:`learn`), the records of
    the pilot's light samples, and the learned selector."""

    def __init__(
        self,
        selector: LightSelector,
        pixels: int,
        pilot: int,
        strategy: int,
        n_bsdf: int,
        m: int,
        stride: int | None = None,
    ):
        self.selector = with_cut(selector)
        self.first = n_bsdf if strategy == MIS else 0  # a camera sample's first light slot
        self.slots = m - self.first if strategy in (MIS, ENV) else 0
        # stride: a render of every stride-th pixel alone (the probe of integrators/picks.py) records all it renders
        self.records = Records(pixels, pilot, self.slots, stride=stride)
        self.recording = True

    def record(self, records: tuple) -> None:
        """Keep the light samples of the pass whose stage records are ``records`` (``_Pass.records``)."""
        c, cams = records[4], records[5]
        if not self.recording or c.sample_start >= self.records.samples:
            return
        in_threads(_record, cams.t.shape[0], *self._record_arguments(records))

    def _record_arguments(self, records: tuple) -> tuple:
        """``_record``'s arguments but the camera samples' range, for the pass whose stage records are ``records``."""
        _s, _env, _lights, sel, c, cams, slots, _acc = records
        r = self.records
        return sel, c, cams, slots, self.first, self.slots, r.samples, r.stride, r.point, r.normal, r.light, r.value

    def compile_kernels(self, records: tuple) -> None:
        """Compile (or load from the cache) the kernels that record the pilot and learn from it, with the types the
        render calls them with, now rather than in the pilot's passes: a first render of its kind does this while
        its compile helper still works on the stages (decisions.md 135).  Nothing is recorded and nothing is learned:
        ``_record`` runs over no camera sample, and ``learned`` over a few made-up records, its result dropped."""
        _record(*self._record_arguments(records), 0, 0)
        learned(self.selector, _made_up_records(self.selector))

    def learn(self) -> LightSelector:
        """The selector learned from the records (kept no longer)."""
        self.selector = learned(self.selector, self.records)
        self.recording = False
        self.records = None
        return self.selector


def _made_up_records(selector: LightSelector, count: int = 64) -> Records:
    """``count`` records along a line, each of a bounded light, every other one blocked: enough for ``learned`` to
    run each of its kernels (it learns nothing from records that no shadow blocked)."""
    records = Records(count, 1, 1, limit=count)
    records.point[:] = np.linspace(0.0, 1.0, records.point.size, dtype=np.float32).reshape(-1, 3)
    records.normal[:, 1] = 1.0
    records.light[:] = np.arange(count) % max(1, selector.n_bounded)
    records.value[:] = np.where(np.arange(count) % 2 == 0, 1.0, -1.0)
    return records


@jit
def _record(sel, c, cams, slots, first, n_light, samples, stride, point, normal, light, value, lo, hi):
    """Camera samples lo .. hi - 1: each light slot of the pass's first ``samples`` samples of every ``stride``-th
    pixel: its shading point and normal, its light, and lum(f L cos V) / the density of the light's point (minus
    what it would have given if the shadow ray was blocked).  Serial, run in threads (``_worksharing.in_threads``:
    as a ``prange`` loop it compiled for 4.1 s, decisions.md 129)."""
    m = c.m
    for k in range(lo, hi):
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
            # blocked: what it would have given, negated (the learning counts it as 0, and weighs how much was lost)
            value[rec] = slots.learn[r] if slots.flags[r] == VISIBLE else -slots.learn[r]
