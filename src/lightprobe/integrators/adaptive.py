"""Per-pixel adaptive sampling (``RenderSettings(adaptive=True)``): a pilot of about spp / 4 samples in every pixel
(the largest power of two that is at most spp / 4), then each pixel's count chosen from its neighbours' pilot noise
(the noisiest of the 8), spp on average.

Why: on the peer scene the error of a uniform 64-spp render sits in a quarter of the pixels (shadowed ground, the
blob, the glossy spheres); spending samples where the noise is cuts the error the image has (its relMSE less the
reference's own noise) by 2.0x at the same mean spp (decisions.md 36).

What it minimises: the metric's sum over pixels of sigma_i^2 / (n_i (mu_i^2 + 0.01)), given sum n_i = spp x
pixels, which is least for n_i proportional to w_i = sigma_i / sqrt(mu_i^2 + 0.01) (Lagrange).  w_i comes from the
pilot, as the largest of the pixel's 8 neighbours' (decision 95: on a thin noisy feature, a small emitter's outline,
their mean diluted it).  Counts are powers of two times the pilot, itself a power of two (a Sobol' pixel's first
2^m samples are a net), from the pilot up to 8 x spp, with the mean at most spp.

Unbiased: pixel i's count is a function of its *neighbours'* pilot samples only (the 3 x 3 ring without the pixel
itself).  A pixel's random numbers depend on its own (seed, pixel) key, so its samples are independent of its
count, and the mean of its n_i samples is an unbiased estimate whatever n_i is.  (Counts taken from the pixel's
own pilot bias it: a pixel whose pilot happened to read low would be given fewer samples to correct it.)  The same
seed gives the same counts and the same image for any thread count or pass size; a render cannot be split into
sample ranges or resumed, since the counts need the whole pilot first.

With a time limit the budget is seconds (``time_pilot_continues``, ``budget_mean``, ``counts_from_noise``,
``next_round``): the pilot doubles (1, 2, 4 ... spp, up to spp / 4) while its next round fits in a quarter of the
limit (half, from 1 to 2 spp); the first plan's mean count is what the rest of the limit buys at the time per
sample of the pilot's last round, times ``COST_FACTOR``; after every round the counts are planned again from the
time the samples after the pilot have actually taken, never below what a pixel has, never above spp on average.
Counts still come from the neighbours' pilot, so the estimate stays unbiased; a limit that leaves room for the
whole plan gives the image of the same render without a limit, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import jit
from .schedule import spread

__all__ = [
    "COST_FACTOR",
    "MAX_FACTOR",
    "PILOT_DIVISOR",
    "PILOT_SHARE",
    "budget_mean",
    "check_spp",
    "counts_from_noise",
    "levels",
    "next_round",
    "pilot_spp",
    "relative_noise",
    "round_passes",
    "sample_counts",
    "sample_rounds",
    "time_pilot_continues",
    "warm_up",
]

PILOT_DIVISOR = 4  # the pilot is at most spp / 4 samples per pixel
MAX_FACTOR = 8  # no pixel gets more than 8 x the mean count
PILOT_SHARE = 0.25  # under a time limit the pilot takes at most a quarter of it
# A time-limited render's first guess of what a sample after the pilot costs, relative to the pilot's: they go to
# the blob, the glossy spheres and the shadows rather than to the sky (peer scene, 64 spp: 19.5 s for the 48 spp
# after a 16-spp pilot against 14.4 s uniform, 1.35x; decisions.md 36-38).  Later plans use the measured time.
COST_FACTOR = 1.35


def check_spp(spp: int) -> str | None:
    """Why ``spp`` cannot be rendered adaptively (None if it can): the pilot needs spp >= 4."""
    if spp < PILOT_DIVISOR:
        return f"adaptive sampling needs spp >= {PILOT_DIVISOR} (a pilot of spp / 4 first), got {spp}"
    return None


def pilot_spp(spp: int) -> int:
    """The pilot's samples per pixel: the largest power of two <= spp / 4 (16 for 64 spp, 16 for 100)."""
    return 1 << (spp // PILOT_DIVISOR).bit_length() - 1


def levels(spp: float, pilot: int | None = None) -> np.ndarray:
    """The counts a pixel can get: the pilot (``pilot_spp(spp)`` unless given) x 2^k, up to 8 x spp."""
    pilot = pilot_spp(int(spp)) if pilot is None else pilot
    return pilot << np.arange(max(1, int(MAX_FACTOR * spp // pilot).bit_length()))


def time_pilot_continues(pilot: int, spp: int, elapsed: float, time_limit: float) -> bool:
    """Whether a time-limited pilot of ``pilot`` samples per pixel, done in ``elapsed`` seconds, doubles once
    more: the next round has as many samples as all before it, so it takes about ``elapsed`` again.  A pilot of
    one sample shows no noise (a pixel's variance needs two), so that first doubling may take up to half the
    limit."""
    share = 2.0 * PILOT_SHARE if pilot == 1 else PILOT_SHARE
    return 2 * pilot <= pilot_spp(spp) and 2.0 * elapsed <= share * time_limit


def budget_mean(pilot: int, spp: int, elapsed: float, time_limit: float, per_spp: float) -> float:
    """The mean count (pilot included) that a time limit affords after a pilot of ``pilot`` samples per pixel,
    ``elapsed`` seconds into the render: the remaining seconds at ``per_spp`` seconds per sample per pixel (the
    pilot's, over the whole image) x ``COST_FACTOR``, at most spp and at least the pilot."""
    if not per_spp > 0.0:
        return float(spp)
    extra = max(0.0, time_limit - elapsed) / (per_spp * COST_FACTOR)
    return float(min(spp, max(pilot, pilot + extra)))


def _ring_max(w: np.ndarray) -> np.ndarray:
    """The largest of each pixel's (up to) 8 neighbours, the pixel itself left out.  The largest, not their mean
    (decision 95): next to a thin noisy feature -- a small bright emitter's outline, one pixel wide -- most of a
    ring is quiet (inside the emitter, or beyond it), and the mean gave the outline's pixels a fraction of the
    noise they show; with the largest, the area-light scene's error at 64 spp fell 2.4x, the many-light scene's
    1.5x, the peer scene's rose 6-8 %."""
    padded = np.pad(w, 1)  # zeros outside the image: a border pixel takes the largest of the neighbours it has
    h, wd = w.shape
    ring = [(dy, dx) for dy in range(3) for dx in range(3) if (dy, dx) != (1, 1)]
    return np.max([padded[dy : dy + h, dx : dx + wd] for dy, dx in ring], axis=0)


def relative_noise(mean: np.ndarray, m2: np.ndarray, count: np.ndarray, width: int, height: int) -> np.ndarray:
    """w per pixel (n_pixels,): the relative noise sigma / sqrt(mu^2 + 0.01) of the pilot (``Accumulator``
    fields), the largest over the pixel's 8 neighbours, not the pixel itself."""
    n = np.maximum(count, 2).astype(np.float64)[:, None]
    sample_var = m2 / (n - 1.0)  # per sample, per channel
    w = np.sqrt((sample_var / (mean * mean + 0.01)).mean(axis=1))
    return _ring_max(np.nan_to_num(w, nan=0.0, posinf=0.0).reshape(height, width)).ravel()


def counts_from_noise(
    w: np.ndarray, pilot: int, spp: float, done: np.ndarray | None = None, budget: float = np.inf
) -> np.ndarray:
    """Samples per pixel (int64) in proportion to ``w`` as levels pilot x 2^k: the largest scale whose mean count
    stays within ``spp`` and, given the samples each pixel has ``done`` (a level; no count falls below it), whose
    samples still to take stay within ``budget``.  No noise anywhere spends the samples evenly."""
    n_pixels = w.size
    done = np.full(n_pixels, pilot, dtype=np.int64) if done is None else done
    cap = min(spp, (done.sum() + budget) / n_pixels)  # the mean if the whole budget went in
    allowed = levels(max(cap, pilot), pilot)
    if not w.max() > 0.0:
        w = np.ones(n_pixels)  # the same level everywhere: the largest the mean and the budget allow
    # level k = pilot x 2^k nearest to scale x w in log2 (ties to the lower), i.e. k = ceil(log2(w / pilot) +
    # log2(scale) - 1/2) clipped to the levels; bisect on log2(scale).  (In log space each step is a few array
    # operations: a search over the levels per pixel took 1.1 s at 512 x 512.)
    noisy = w > 0.0
    lw = np.full(w.shape, -np.inf)
    lw[noisy] = np.log2(w[noisy] / pilot)
    lo, hi = -lw[noisy].max() - 1.0, allowed.size - lw[noisy].min()  # at lo every pixel at the pilot, at hi the cap
    for _ in range(60):  # the largest scale that fits
        mid = 0.5 * (lo + hi)
        total, extra = _totals(lw, allowed, done, mid)
        if total <= spp * n_pixels and extra <= budget:
            lo = mid
        else:
            hi = mid
    top = allowed.size - 1
    return np.maximum(allowed[np.clip(np.ceil(lw + (lo - 0.5)), 0, top).astype(np.int64)], done)


def warm_up() -> None:
    """Load (or compile, ~0.4 s on a first run) the planner's loop, so that a render does it before its clock."""
    counts_from_noise(np.ones(1), 1, 1.0)


@jit
def _totals(lw, allowed, done, shift):
    """(sum of the counts, sum of the samples still to take) at ``shift``: one loop, where the array expression
    took 2.5 ms a step at 512 x 512, and a time-limited render plans again after every round."""
    top = allowed.shape[0] - 1
    total = 0
    extra = 0
    for i in range(lw.shape[0]):
        k = 0
        if lw[i] > -math.inf:
            k = min(max(math.ceil(lw[i] + (shift - 0.5)), 0), top)
        c = max(allowed[k], done[i])
        total += c
        extra += c - done[i]
    return total, extra


def sample_counts(
    mean: np.ndarray,
    m2: np.ndarray,
    count: np.ndarray,
    width: int,
    height: int,
    spp: float,
    pilot: int | None = None,
):
    """Samples per pixel (n_pixels,) int64 from the pilot's per-pixel statistics (``Accumulator`` fields), ``spp``
    on average at most (a time limit's mean may be fractional); ``pilot`` defaults to ``pilot_spp(spp)``."""
    pilot = pilot_spp(int(spp)) if pilot is None else pilot
    return counts_from_noise(relative_noise(mean, m2, count, width, height), pilot, spp)


def round_passes(chosen: np.ndarray, level: int, largest_pass: int):
    """(pixels, samples per pixel, first sample index) of the passes that give samples level .. 2 level - 1 to
    the pixels ``chosen``, at most ``largest_pass`` camera samples each."""
    chosen = spread(chosen)  # both threads get a share of every part of the image
    spp_pass = max(1, min(level, largest_pass // chosen.size))
    band = max(1, largest_pass // spp_pass)
    for start in range(level, 2 * level, spp_pass):
        spp_now = min(spp_pass, 2 * level - start)
        for i in range(0, chosen.size, band):
            yield chosen[i : i + band], spp_now, start


def next_round(done: np.ndarray, counts: np.ndarray) -> tuple[int, np.ndarray] | None:
    """The next round of a render whose pixels hold ``done`` samples and are to get ``counts`` (both levels): the
    lowest level L any pixel still needs, and the pixels at L that need more; None when every count is met."""
    short = counts > done
    if not short.any():
        return None
    level = int(done[short].min())
    return level, np.flatnonzero(short & (done == level))


def sample_rounds(counts: np.ndarray, pilot: int, largest_pass: int, replan=None):
    """(pixels, samples per pixel, first sample index) of the passes after the pilot: round L gives samples
    L .. 2L - 1 to the pixels whose count exceeds L, for L = pilot, 2 pilot, ...  Each pass holds at most
    ``largest_pass`` camera samples, and a pixel's samples come in index order.  ``replan(done)``, if given, is
    called after every round with the samples each pixel holds and returns the counts from then on (at least
    ``done``); the next round then starts at the lowest level a pixel still needs."""
    done = np.full(counts.shape, pilot, dtype=np.int64)
    while (step := next_round(done, counts)) is not None:
        level, chosen = step
        yield from round_passes(chosen, level, largest_pass)
        done[chosen] = 2 * level
        if replan is not None:
            counts = replan(done)
