"""Per-pixel adaptive sampling (``RenderSettings(adaptive=True)``): a pilot of about spp / 4 samples in every pixel
(the largest power of two that is at most spp / 4), then each pixel's count chosen from its neighbours' pilot noise,
spp on average.

Why: on the peer scene the error of a uniform 64-spp render sits in a quarter of the pixels (shadowed ground, the
blob, the glossy spheres); spending samples where the noise is cuts the error the image has (its relMSE less the
reference's own noise) by 2.0x at the same mean spp (decisions.md 36).

What it minimises: the metric's sum over pixels of sigma_i^2 / (n_i (mu_i^2 + 0.01)), given sum n_i = spp x
pixels, which is least for n_i proportional to w_i = sigma_i / sqrt(mu_i^2 + 0.01) (Lagrange).  sigma_i and mu_i
come from the pilot.  Counts are powers of two times the pilot, itself a power of two (a Sobol' pixel's first 2^m
samples are a net), from the pilot up to 8 x spp, with the mean at most spp.

Unbiased: pixel i's count is a function of its *neighbours'* pilot samples only (the 3 x 3 ring without the pixel
itself).  A pixel's random numbers depend on its own (seed, pixel) key, so its samples are independent of its
count, and the mean of its n_i samples is an unbiased estimate whatever n_i is.  (Counts taken from the pixel's
own pilot bias it: a pixel whose pilot happened to read low would be given fewer samples to correct it.)  The same
seed gives the same counts and the same image for any thread count or pass size; a render cannot be split into
sample ranges or resumed, since the counts need the whole pilot first.

With a time limit the budget is seconds (``time_pilot_continues``, ``budget_mean``): the pilot doubles (1, 2, 4 ...
spp, up to spp / 4) while its next round fits in a quarter of the limit (half, from 1 to 2 spp), and the mean
count is what the rest of the limit buys at the time per sample of the pilot's last round, times ``COST_FACTOR``
(never more than spp).  Counts still come from the neighbours' pilot, so the estimate stays unbiased; a limit
that leaves room for the whole plan gives the image of the same render without a limit, bit for bit.
"""

from __future__ import annotations

import numpy as np

from .schedule import spread

__all__ = [
    "COST_FACTOR",
    "MAX_FACTOR",
    "PILOT_DIVISOR",
    "PILOT_SHARE",
    "budget_mean",
    "check_spp",
    "levels",
    "pilot_spp",
    "sample_counts",
    "sample_rounds",
    "time_pilot_continues",
]

PILOT_DIVISOR = 4  # the pilot is at most spp / 4 samples per pixel
MAX_FACTOR = 8  # no pixel gets more than 8 x the mean count
PILOT_SHARE = 0.25  # under a time limit the pilot takes at most a quarter of it
# The samples after the pilot cost this much more per camera sample than the pilot's: they go to the blob, the
# glossy spheres and the shadows rather than to the sky (peer scene, 64 spp: 19.5 s for the 48 spp after a 16-spp
# pilot against 14.4 s uniform, 1.35x; decisions.md 36-38).
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


def _ring_mean(w: np.ndarray) -> np.ndarray:
    """Mean of each pixel's (up to) 8 neighbours, the pixel itself left out."""
    padded = np.pad(w, 1)
    inside = np.pad(np.ones_like(w), 1)
    h, wd = w.shape
    ring = [(dy, dx) for dy in range(3) for dx in range(3) if (dy, dx) != (1, 1)]  # summed without the centre:
    total = sum(padded[dy : dy + h, dx : dx + wd] for dy, dx in ring)  # subtracting it would leave its rounding
    count = sum(inside[dy : dy + h, dx : dx + wd] for dy, dx in ring)
    return np.where(count > 0, total / np.maximum(count, 1.0), 0.0)


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
    n = np.maximum(count, 2).astype(np.float64)[:, None]
    sample_var = m2 / (n - 1.0)  # per sample, per channel
    w = np.sqrt((sample_var / (mean * mean + 0.01)).mean(axis=1))
    w = _ring_mean(np.nan_to_num(w, nan=0.0, posinf=0.0).reshape(height, width)).ravel()
    allowed = levels(spp, pilot)
    if not w.max() > 0.0:  # no noise seen anywhere: spend the samples evenly (spp itself if it is a level)
        return np.full(width * height, allowed[allowed <= spp].max(), dtype=np.int64)
    # counts proportional to w, as levels: level k = pilot x 2^k nearest to scale x w in log2 (ties to the lower),
    # i.e. k = ceil(log2(w / pilot) + log2(scale) - 1/2) clipped to the levels; bisect on log2(scale).  (In log
    # space each step is a few array operations: a search over the levels per pixel took 1.1 s at 512 x 512.)
    top = allowed.size - 1
    noisy = w > 0.0
    lw = np.full(w.shape, -np.inf)
    lw[noisy] = np.log2(w[noisy] / allowed[0])

    def counts_for(shift: float) -> np.ndarray:
        return allowed[np.clip(np.ceil(lw + (shift - 0.5)), 0, top).astype(np.int64)]

    lo, hi = -lw[noisy].max() - 1.0, top + 1.0 - lw[noisy].min()  # at lo every pixel at the pilot, at hi the cap
    for _ in range(60):  # the largest scale whose mean count stays within spp
        mid = 0.5 * (lo + hi)
        if counts_for(mid).mean() > spp:
            hi = mid
        else:
            lo = mid
    return counts_for(lo)


def sample_rounds(counts: np.ndarray, pilot: int, largest_pass: int):
    """(pixels, samples per pixel, first sample index) of the passes after the pilot: round L gives samples
    L .. 2L - 1 to the pixels whose count exceeds L, for L = pilot, 2 pilot, ...  Each pass holds at most
    ``largest_pass`` camera samples, and a pixel's samples come in index order."""
    level = pilot
    while level < counts.max():
        chosen = spread(np.flatnonzero(counts > level))  # both threads get a share of every part of the image
        spp_pass = max(1, min(level, largest_pass // chosen.size))
        band = max(1, largest_pass // spp_pass)
        for start in range(level, 2 * level, spp_pass):
            spp_now = min(spp_pass, 2 * level - start)
            for i in range(0, chosen.size, band):
                yield chosen[i : i + band], spp_now, start
        level *= 2
