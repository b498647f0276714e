"""Adaptive sample counts from a pilot's statistics (integrators/adaptive.py)."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.integrators.adaptive import (
    COST_FACTOR,
    MAX_FACTOR,
    budget_mean,
    counts_from_noise,
    levels,
    next_round,
    pilot_spp,
    sample_counts,
    sample_rounds,
    time_pilot_continues,
)


def pilot_stats(variance: np.ndarray, mean: float = 1.0, count: int = 16):
    """Accumulator fields of a pilot whose per-sample variance per pixel is ``variance`` (H, W)."""
    h, w = variance.shape
    m2 = np.repeat(variance.reshape(-1, 1) * (count - 1), 3, axis=1)
    return np.full((h * w, 3), mean), m2, np.full(h * w, count), w, h


def test_a_pixel_is_sampled_by_its_neighbours_noise_not_its_own():
    """One noisy pixel in a quiet image: its 8 neighbours get more samples than the others, and the pixel itself
    no more than a quiet one with quiet neighbours -- its own pilot never decides its count (which would bias it)."""
    variance = np.full((7, 7), 0.01)
    variance[3, 3] = 100.0
    counts = sample_counts(*pilot_stats(variance), spp=64).reshape(7, 7)
    ring = np.zeros((7, 7), bool)
    ring[2:5, 2:5] = True
    ring[3, 3] = False
    assert counts[ring].min() > counts[~ring].max()  # the ring above every other pixel, the noisy one included
    assert counts[3, 3] <= counts[0, 0]
    assert counts.mean() <= 64


def test_a_thin_noisy_line_gives_its_neighbours_its_own_noise():
    """A one-pixel-wide noisy column (a small emitter's outline) in a quiet image: the pixels beside it get the count
    that the line's noise asks for, not a third of it -- the noisiest neighbour decides, not the ring's mean (which
    left an outline pixel with 3 noisy neighbours of 8 below one with all 8 noisy: decision 95)."""
    variance = np.full((9, 9), 0.01)
    variance[:, 4] = 100.0
    counts = sample_counts(*pilot_stats(variance), spp=64).reshape(9, 9)
    beside = counts[1:-1, [3, 5]]
    line = counts[1:-1, 4]  # its own neighbours on the line are as noisy as it is
    assert beside.min() == counts.max() and line.max() == counts.max()  # all at the noisiest level
    assert counts[:, [0, 1, 7, 8]].max() < counts.max()  # quiet pixels away from it stay below
    assert counts.mean() <= 64


def test_counts_follow_the_noise_within_the_budget():
    rng = np.random.default_rng(0)
    variance = np.exp(rng.normal(0.0, 2.0, (16, 24)))
    counts = sample_counts(*pilot_stats(variance), spp=64)
    assert counts.mean() <= 64 and counts.mean() > 48  # the budget, nearly all of it
    assert set(np.unique(counts)) <= {16 * 2**k for k in range(6)}  # pilot x 2^k up to 8 spp
    assert counts.max() <= MAX_FACTOR * 64
    # a noiseless image spends its samples evenly
    np.testing.assert_array_equal(sample_counts(*pilot_stats(np.zeros((4, 5))), spp=64), np.full(20, 64))


def test_rounds_give_each_pixel_its_samples_in_order():
    counts = np.array([16, 32, 64, 256, 16, 128])
    taken = {p: [] for p in range(6)}
    for pixels, spp_now, start in sample_rounds(counts, 16, largest_pass=40):
        assert pixels.size * spp_now <= 40
        for p in pixels:
            taken[int(p)].extend(range(start, start + spp_now))
    for p, n in enumerate(counts):
        assert taken[p] == list(range(16, n))  # after the pilot's 0 .. 15, every index once, in order
    # planned again after every round (a time limit): a finished pixel given more continues where it stopped
    later = np.array([64, 32, 64, 32])
    taken = {p: [] for p in range(4)}
    for pixels, spp_now, start in sample_rounds(np.array([16, 32, 64, 16]), 16, 40, lambda done: later):
        for p in pixels:
            taken[int(p)].extend(range(start, start + spp_now))
    for p, n in enumerate(later):
        assert taken[p] == list(range(16, n))


def test_any_spp_from_4_has_a_power_of_two_pilot_and_keeps_the_budget():
    """The pilot is the largest power of two <= spp / 4, so every count (pilot x 2^k) is a Sobol' net."""
    assert [pilot_spp(n) for n in (4, 7, 8, 12, 16, 64, 100, 1000)] == [1, 1, 2, 2, 4, 16, 16, 128]
    np.testing.assert_array_equal(levels(100), [16, 32, 64, 128, 256, 512])  # up to 8 x spp
    rng = np.random.default_rng(1)
    variance = np.exp(rng.normal(0.0, 2.0, (16, 24)))
    counts = sample_counts(*pilot_stats(variance), spp=100)
    assert 80 < counts.mean() <= 100
    assert set(np.unique(counts)) <= set(levels(100).tolist())
    # no noise anywhere: the largest level within the budget, everywhere
    np.testing.assert_array_equal(sample_counts(*pilot_stats(np.zeros((4, 5))), spp=100), np.full(20, 64))


def test_a_time_limit_plans_the_pilot_and_the_mean_count():
    """Under a time limit the pilot doubles while its next round (as long as all before it) fits in a quarter of
    the limit, up to spp / 4; the mean count is what the rest buys at the pilot's time per sample x COST_FACTOR."""
    assert time_pilot_continues(4, 64, 1.0, 10.0)  # 2 x 1 s within 2.5 s
    assert not time_pilot_continues(4, 64, 1.5, 10.0)  # 3 s would not be
    assert not time_pilot_continues(16, 64, 1e-3, 10.0)  # spp / 4 reached
    assert time_pilot_continues(1, 64, 2.0, 10.0)  # one sample shows no noise: 1 -> 2 may take half the limit
    assert not time_pilot_continues(1, 64, 2.6, 10.0) and not time_pilot_continues(2, 64, 2.0, 10.0)
    assert budget_mean(4, 1000, 2.0, 10.0, 0.5) == pytest.approx(4 + 8.0 / (0.5 * COST_FACTOR))
    assert budget_mean(4, 12, 2.0, 10.0, 0.5) == 12  # never above spp (4 + 11.9 without the cap)
    assert budget_mean(4, 1000, 12.0, 10.0, 0.5) == 4  # the limit spent: the pilot alone
    rng = np.random.default_rng(2)
    variance = np.exp(rng.normal(0.0, 2.0, (16, 24)))
    counts = sample_counts(*pilot_stats(variance, count=2), spp=10.5, pilot=2)  # a fractional mean
    assert 8 < counts.mean() <= 10.5 and counts.min() == 2
    assert set(np.unique(counts)) <= set(levels(10.5, 2).tolist()) == {2, 4, 8, 16, 32, 64}


def test_counts_planned_again_keep_what_is_done_and_fit_the_budget():
    """A time-limited render plans again after every round: no count falls below what a pixel has done, the
    samples still to take fit the budget (nearly all of it), and the next round starts at the lowest level a pixel
    still needs -- below the current one if the new plan gives a finished pixel more."""
    rng = np.random.default_rng(3)
    w = np.exp(rng.normal(0.0, 1.5, 4000))
    first = counts_from_noise(w, 4, 32.0)
    done = np.minimum(first, 8)  # the rounds at 4 are over
    for budget in (0.0, 2000.0, 40000.0):
        more = counts_from_noise(w, 4, 4096, done, budget)
        extra = (more - done).sum()
        assert (more >= done).all() and extra <= budget and extra >= 0.75 * budget
        assert set(np.unique(more)) <= {4 << k for k in range(16)}
    np.testing.assert_array_equal(counts_from_noise(w, 4, 32.0, np.full(4000, 4), np.inf), first)
    done = np.array([4, 8, 8, 16])
    level, chosen = next_round(done, np.array([16, 16, 8, 16]))
    assert level == 4 and chosen.tolist() == [0]
    level, chosen = next_round(np.array([8, 8, 8, 16]), np.array([16, 16, 8, 16]))
    assert level == 8 and chosen.tolist() == [0, 1]
    assert next_round(done, done) is None
