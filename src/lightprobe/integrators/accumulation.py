"""Accumulation: each pixel's samples added in sample order to a running mean and variance, and the image they give.

The last stage of a pass (:func:`accumulate`) adds each camera sample's value -- what its camera ray saw directly plus
its visible slots' contributions -- to its pixel's running float64 mean and M2 (Welford), in sample order, so that
the image is bit-identical for any pass size and thread count.  A non-finite value counts as 0 and is counted
(``nonfinite``).  :class:`Accumulator` holds those statistics between passes and renders: a render continues one
(``render(..., resume=acc)``, bit for bit the same as not stopping), and :meth:`Accumulator.merged` combines two over
disjoint sample ranges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._numba import jit_body
from ..errors import ParameterError
from .pass_state import AccumulatorArrays
from .techniques import VISIBLE

__all__ = ["Accumulator", "RenderResult", "accumulate", "pass_pixels_count", "result_from"]


def pass_pixels_count(c, cams, slots):
    """The stage's items: the pass's pixels."""
    return c.pixels.shape[0]


@jit_body
def accumulate(c, cams, slots, acc, lo, hi):
    """Pixels lo .. hi - 1 of the pass: their samples, in order."""
    m, spp_pass = c.m, c.spp_pass
    mean, m2, count, nonfinite = acc.mean, acc.m2, acc.count, acc.nonfinite
    for q in range(lo, hi):
        p = c.pixels[q]
        for j in range(spp_pass):
            k = q * spp_pass + j
            vr, vg, vb = cams.direct[k, 0], cams.direct[k, 1], cams.direct[k, 2]
            for i in range(k * m, k * m + m):
                if slots.flags[i] == VISIBLE:
                    vr += slots.contrib[i, 0]
                    vg += slots.contrib[i, 1]
                    vb += slots.contrib[i, 2]
            if not (math.isfinite(vr) and math.isfinite(vg) and math.isfinite(vb)):
                vr = vg = vb = 0.0
                nonfinite[p] += 1
            count[p] += 1
            n = count[p]
            d0 = vr - mean[p, 0]
            d1 = vg - mean[p, 1]
            d2 = vb - mean[p, 2]
            mean[p, 0] += d0 / n
            mean[p, 1] += d1 / n
            mean[p, 2] += d2 / n
            m2[p, 0] += d0 * (vr - mean[p, 0])
            m2[p, 1] += d1 * (vg - mean[p, 1])
            m2[p, 2] += d2 * (vb - mean[p, 2])


class Accumulator:
    """Per-pixel running statistics in float64: mean, M2 (sum of squared deviations, Welford), sample and
    non-finite counts.  A render continues one (``render(..., resume=acc)``, bit for bit the same as not
    stopping); :meth:`merged` combines two over disjoint sample ranges."""

    def __init__(self, n_pixels: int):
        self.mean = np.zeros((n_pixels, 3))
        self.m2 = np.zeros((n_pixels, 3))
        self.count = np.zeros(n_pixels, dtype=np.int64)
        self.nonfinite = np.zeros(n_pixels, dtype=np.int64)
        #: written by an adaptive render (per-pixel counts from its pilot): it cannot be merged with a sample range
        self.adaptive = False
        #: what a render's light selection learned (integrators/light_learning.table_of), for a render that
        #: continues these statistics to pick as the render that did not stop would have; None: nothing learned
        self.learned: dict | None = None

    def arrays(self) -> AccumulatorArrays:
        """The record the accumulation stage writes."""
        return AccumulatorArrays(self.mean, self.m2, self.count, self.nonfinite)

    def add(self, values: np.ndarray) -> None:
        """One more sample of every pixel, ``values`` (n_pixels, 3), by :func:`accumulate`'s update (Welford; a
        non-finite value counts as 0 and is counted), for callers that hold a whole pass in NumPy (the laboratory's
        estimator, ``lab/render.py``)."""
        finite = np.all(np.isfinite(values), axis=1)
        values = np.where(finite[:, None], values, 0.0)
        self.nonfinite += ~finite
        self.count += 1
        n = self.count[:, None].astype(np.float64)
        delta = values - self.mean
        self.mean += delta / n
        self.m2 += delta * (values - self.mean)

    def resume_problem(self, first_sample: int) -> str | None:
        """Why a render from sample ``first_sample`` cannot continue these statistics (None if it can): every pixel
        must hold exactly ``first_sample`` samples -- not an adaptive render's counts, not a pass cut short, and no
        sample taken again."""
        if np.all(self.count == first_sample):
            return None
        return (
            f"resume: the accumulator holds {self.count.min()}..{self.count.max()} samples per pixel, the render "
            f"starts at sample {first_sample} (first_sample must be the count every pixel holds)"
        )

    def copy(self) -> Accumulator:
        other = Accumulator(0)
        other.mean, other.m2 = self.mean.copy(), self.m2.copy()
        other.count, other.nonfinite = self.count.copy(), self.nonfinite.copy()
        other.adaptive = self.adaptive
        other.learned = None if self.learned is None else {k: np.copy(v) for k, v in self.learned.items()}
        return other

    def merged(self, other: Accumulator) -> Accumulator:
        """Both sample sets as one: Chan, Golub and LeVeque's pairwise update (1979), mean_ab = mean_a + delta
        n_b / n and M2_ab = M2_a + M2_b + delta^2 n_a n_b / n.  Equal to a single run up to float64 rounding."""
        if self.mean.shape != other.mean.shape:
            raise ParameterError(f"cannot merge renders of {self.count.size} and {other.count.size} pixels")
        if self.adaptive or other.adaptive:
            # its pixels hold samples 0 .. count - 1, which another range's samples may repeat (decisions.md 99)
            raise ParameterError(
                "cannot merge an adaptive render's statistics with another's (its per-pixel counts came from its "
                "pilot): render the sample ranges with adaptive=False"
            )
        out = Accumulator(0)
        na, nb = self.count[:, None].astype(float), other.count[:, None].astype(float)
        n = na + nb
        delta = other.mean - self.mean
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(n > 0, nb / n, 0.0)
            out.mean = self.mean + delta * share
            out.m2 = self.m2 + other.m2 + np.where(n > 0, delta**2 * na * nb / n, 0.0)
        out.count = self.count + other.count
        out.nonfinite = self.nonfinite + other.nonfinite
        out.learned = self.learned if self.learned is not None else other.learned
        return out

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {
            "mean": self.mean,
            "m2": self.m2,
            "count": self.count,
            "nonfinite": self.nonfinite,
            "adaptive": np.array(self.adaptive),
            **{f"learned_{k}": np.asarray(v) for k, v in (self.learned or {}).items()},
        }

    @classmethod
    def from_arrays(cls, arrays) -> Accumulator:
        acc = cls(0)
        acc.mean = np.array(arrays["mean"], np.float64)
        acc.m2 = np.array(arrays["m2"], np.float64)
        acc.count = np.array(arrays["count"], np.int64)
        acc.nonfinite = np.array(arrays["nonfinite"], np.int64)
        acc.adaptive = bool(arrays["adaptive"]) if "adaptive" in arrays else False  # older files: uniform renders
        learned = {k.removeprefix("learned_"): np.array(arrays[k]) for k in arrays if k.startswith("learned_")}
        acc.learned = learned or None
        return acc


@dataclass
class RenderResult:
    """Mean radiance (H, W, 3), variance of that mean (H, W, 3), samples per pixel (H, W), and statistics."""

    image: np.ndarray
    variance: np.ndarray
    counts: np.ndarray
    stats: dict = field(default_factory=dict)
    #: the running float64 sums (mean, M2, counts) that produced the image: resume or merge from them
    accumulator: Accumulator | None = None


def result_from(acc: Accumulator, width: int, height: int, stats: dict | None = None) -> RenderResult:
    """The image (float32 mean, never NaN/Inf), the variance of each pixel's mean, and the counts of ``acc``."""
    counts = acc.count
    if counts.size != width * height:
        raise ParameterError(f"{counts.size} pixels are not a {width}x{height} image")
    with np.errstate(divide="ignore", invalid="ignore"):
        var = np.where((counts >= 2)[:, None], acc.m2 / (counts * np.maximum(counts - 1, 1))[:, None], 0.0)
    image = np.nan_to_num(acc.mean.reshape(height, width, 3), nan=0.0, posinf=0.0, neginf=0.0)
    return RenderResult(
        image.astype(np.float32),
        np.nan_to_num(var.reshape(height, width, 3), nan=0.0, posinf=0.0).astype(np.float32),
        counts.reshape(height, width),
        stats if stats is not None else {},
        acc,
    )
