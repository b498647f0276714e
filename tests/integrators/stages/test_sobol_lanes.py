"""The shading slots' Sobol' numbers in 8 integer lanes are the scalar sampler's, bit for bit."""

import numpy as np
import pytest
from numba import njit

from lightprobe.integrators.stages.sobol_lanes import LANES, camera_numbers_block, slot_numbers_block
from lightprobe.integrators.techniques import BRDF, MIS, technique_slot
from lightprobe.sampling.rng import SAMPLERS, sample_state, uniform, uniform_2d

SOBOL = SAMPLERS["sobol"]


@njit
def _lanes(seed, pixels, samples, strategy, n_bsdf, m):
    out = np.full((pixels.shape[0] * m + 1, 3), -7.0)  # one row past the last camera sample's: must stay untouched
    for k in range(pixels.shape[0]):
        rs = sample_state(SOBOL, seed, pixels[k], samples[k])
        for first in range(0, m, LANES):
            slot_numbers_block(out, rs[2], rs[3], strategy == MIS, n_bsdf, m, k * m + first, first)
    return out


@njit
def _scalar(seed, pixels, samples, strategy, n_bsdf, m):
    out = np.full((pixels.shape[0] * m + 1, 3), -7.0)
    for k in range(pixels.shape[0]):
        rs = sample_state(SOBOL, seed, pixels[k], samples[k])
        for j in range(m):
            rj, slot = technique_slot(rs, strategy, n_bsdf, m - n_bsdf, j)
            u0, u1 = uniform_2d(rj, 2 + 3 * slot)
            out[k * m + j, 0] = u0
            out[k * m + j, 1] = u1
            out[k * m + j, 2] = uniform(rj, 4 + 3 * slot)
    return out


@pytest.mark.parametrize(
    ("strategy", "n_bsdf", "m"),
    [(MIS, 4, 8), (MIS, 2, 3), (MIS, 1, 2), (MIS, 5, 13), (MIS, 0, 4), (BRDF, 1, 1), (BRDF, 9, 9)],
)
def test_slot_numbers_in_lanes_are_the_scalar_samplers(strategy, n_bsdf, m):
    rng = np.random.default_rng(m * 31 + n_bsdf)
    pixels = rng.integers(0, 1 << 20, 3000)
    samples = rng.integers(0, 1 << 12, 3000)
    samples[:4] = [0, (1 << 32) - 1, 1 << 32, (1 << 40) + 12345]  # indices past 2^32 start a fresh scramble
    seed = int(rng.integers(0, 1 << 31))
    lanes = _lanes(seed, pixels, samples, strategy, n_bsdf, m)
    scalar = _scalar(seed, pixels, samples, strategy, n_bsdf, m)
    assert np.array_equal(lanes, scalar)
    assert np.all(lanes[-1] == -7.0)
    assert np.all((lanes[:-1] >= 0.0) & (lanes[:-1] < 1.0))


@njit
def _camera_lanes(seed, pixels, spp_pass, sample_start, n):
    dirs = np.full((n, 3), -7.0)
    for start in range(0, n, LANES):
        camera_numbers_block(dirs[: n - 1], seed, pixels, spp_pass, sample_start, start)  # all but the last
    return dirs


@njit
def _camera_scalar(seed, pixels, spp_pass, sample_start, n):
    dirs = np.full((n, 3), -7.0)
    for k in range(n - 1):
        rs = sample_state(SOBOL, seed, pixels[k // spp_pass], sample_start + k % spp_pass)
        dirs[k, 0], dirs[k, 1] = uniform_2d(rs, 0)
        dirs[k, 2] = 0.0
    return dirs


@pytest.mark.parametrize(("spp_pass", "sample_start"), [(1, 0), (3, 5), (64, 1 << 20), (2, (1 << 32) - 1)])
def test_camera_numbers_in_lanes_are_the_scalar_samplers(spp_pass, sample_start):
    """The camera rays' positions in their pixels (dimensions 0 and 1) for every camera sample of a pass: pixel
    k // spp_pass, sample index sample_start + k % spp_pass (across 2^32, where a fresh scramble starts), a pass
    whose length is not a multiple of 8 (the row after it stays untouched)."""
    rng = np.random.default_rng(spp_pass)
    n = 2 * 1000 * spp_pass + 4  # 250 spp_pass blocks of 8 and a partial one (the last row excluded)
    pixels = rng.integers(0, 1 << 20, n // spp_pass + 1)
    seed = int(rng.integers(0, 1 << 31))
    lanes = _camera_lanes(seed, pixels, spp_pass, sample_start, n)
    scalar = _camera_scalar(seed, pixels, spp_pass, sample_start, n)
    assert np.array_equal(lanes, scalar)
    assert np.all(lanes[-1] == -7.0)
    assert np.all((lanes[:-1, :2] >= 0.0) & (lanes[:-1, :2] < 1.0)) and len(np.unique(lanes[:-1, 0])) > n // 2
