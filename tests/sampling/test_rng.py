"""The samplers' own properties: purity, stratification (Sobol'), uniformity, decorrelated pixels."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from scipy import stats

from lightprobe.sampling import rng

SOBOL, INDEPENDENT = rng.SAMPLERS["sobol"], rng.SAMPLERS["independent"]
# the renderer's layout: (0, 1) the pixel, (2 + 3j, 3 + 3j) slot j's direction, 4 + 3j its 1D choice
PAIRS = [(0, 1), (2, 3), (5, 6), (8, 9)]


def _one_pixel(sampler, pixel=12345, n=1 << 10, dims=11, seed=7):
    return rng.sampler_batch(sampler, seed, np.full(n, pixel, np.int64), np.arange(n, dtype=np.int64), dims)


@pytest.mark.parametrize("k", [2, 5, 8, 10])
def test_sobol_prefixes_are_stratified_in_every_dimension(k):
    u = _one_pixel(SOBOL)[: 1 << k]
    for d in range(u.shape[1]):
        counts = np.bincount((u[:, d] * (1 << k)).astype(int), minlength=1 << k)
        assert (counts == 1).all(), d


@pytest.mark.parametrize("k", [4, 7, 8])
def test_sobol_pairs_are_nets(k):
    """The first 2^k points of each 2D pair: one point in every elementary interval of area 2^-k (a (0, k, 2)-net)."""
    u = _one_pixel(SOBOL)[: 1 << k]
    for a, b in PAIRS:
        for bits_x in range(k + 1):
            bits_y = k - bits_x
            cells = (u[:, a] * (1 << bits_x)).astype(int) * (1 << bits_y) + (u[:, b] * (1 << bits_y)).astype(int)
            assert np.bincount(cells, minlength=1 << k).max() == 1, (a, b, bits_x)


def test_sobol_second_dimension_is_its_direction_numbers():
    """rng._sobol_y (a superset sum over GF(2), reversed) is the XOR of the direction numbers v_k of the index's set
    bits, v_0 = 2^31 and v_{k+1} = v_k ^ (v_k >> 1): on each of the 32 one-bit indices, which decides every index
    of a linear map, and on random ones."""
    columns = [1 << 31]
    for _ in range(31):
        columns.append(columns[-1] ^ (columns[-1] >> 1))

    def by_definition(i):
        y = 0
        for k in range(32):
            if i >> k & 1:
                y ^= columns[k]
        return y

    indices = [1 << k for k in range(32)] + [int(i) for i in np.random.default_rng(5).integers(0, 1 << 32, 2000)]
    for i in indices:
        assert int(rng._sobol_y(np.uint64(i))) == by_definition(i), i


def test_independent_points_are_not_stratified():
    """Negative control: the same check rejects the independent sampler."""
    u = _one_pixel(INDEPENDENT)[:256]
    assert (np.bincount((u[:, 0] * 256).astype(int), minlength=256) != 1).any()


@pytest.mark.parametrize("sampler", ["sobol", "independent"])
def test_values_across_pixels_are_uniform_and_decorrelated(sampler):
    code = rng.SAMPLERS[sampler]
    pixels = np.arange(200_000, dtype=np.int64)
    for sample in (0, 1, 37):
        u = rng.sampler_batch(code, 3, pixels, np.full(pixels.size, sample, np.int64), 8)
        for d in range(8):
            assert stats.kstest(u[:, d], "uniform").pvalue > 1e-4, (sample, d)
            # neighbouring pixels (the same sample index) and neighbouring dimensions are uncorrelated
            assert abs(np.corrcoef(u[:-1, d], u[1:, d])[0, 1]) < 0.015
            if d + 1 < 8:
                assert abs(np.corrcoef(u[:, d], u[:, d + 1])[0, 1]) < 0.015


def test_values_are_a_pure_function_of_their_coordinates():
    rs = np.random.default_rng(0)
    pixels = rs.integers(0, 1 << 30, 5000)
    samples = rs.integers(0, 1 << 20, 5000)
    for code in rng.SAMPLERS.values():
        a = rng.sampler_batch(code, 11, pixels, samples, 9)
        order = rs.permutation(5000)
        b = rng.sampler_batch(code, 11, pixels[order], samples[order], 9)
        np.testing.assert_array_equal(a[order], b)
        assert (a >= 0).all() and (a < 1).all()
        assert not np.array_equal(a, rng.sampler_batch(code, 12, pixels, samples, 9))  # the seed matters


def test_independent_sampler_keeps_the_original_hash():
    pixels = np.arange(100, dtype=np.int64)
    samples = np.arange(100, dtype=np.int64) * 3
    np.testing.assert_array_equal(
        rng.sampler_batch(INDEPENDENT, 5, pixels, samples, 7), rng.uniform_batch(5, pixels, samples, 7)
    )


def test_owen_scramble_is_a_nested_bijection():
    values = np.arange(1 << 16, dtype=np.uint64) << np.uint64(16)  # every top-16-bit prefix once
    out = np.array([rng.owen_scramble(v, np.uint64(0x1234567)) for v in values[:4096]], np.uint64)
    assert np.unique(out).size == out.size
    # Owen scrambling permutes each level of the tree: the output's top b bits depend only on the input's top b bits
    top = np.array([rng.owen_scramble(v | np.uint64(0xFFFF), np.uint64(0x1234567)) for v in values[:4096]], np.uint64)
    assert np.array_equal(out >> np.uint64(16), top >> np.uint64(16))


@numba.njit
def _pairs_both_ways(sampler, seed, pixel, sample, dim):
    state = rng.sample_state(sampler, seed, pixel, sample)
    return rng.uniform_2d(state, dim), (rng.uniform(state, dim), rng.uniform(state, dim + 1))


@pytest.mark.parametrize("sampler", [SOBOL, INDEPENDENT])
def test_uniform_2d_gives_the_numbers_of_two_uniform_calls(sampler):
    """The renderer draws each pair with one call; the numbers (and so every image) are those of the per-dimension
    function that the purity, stratification and split-and-merge tests check."""
    for pixel, sample in [(0, 0), (12345, 17), (7, 1 << 20), (99, (1 << 32) + 3)]:
        for a, _ in PAIRS:
            paired, single = _pairs_both_ways(sampler, 5, pixel, sample, a)
            assert paired == single, (pixel, sample, a)
