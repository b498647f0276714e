"""The shading slots' Sobol' numbers in 8 integer lanes are the scalar sampler's, bit for bit."""

import numpy as np
import pytest
from numba import njit

from lightprobe.integrators.stages.sobol_lanes import LANES, camera_numbers_block, slot_numbers_run
from lightprobe.integrators.techniques import BRDF, MIS, technique_slot
from lightprobe.sampling.rng import SAMPLERS, sample_state, uniform, uniform_2d

SOBOL = SAMPLERS["sobol"]


@njit
def _lanes(seed, pixels, spp_pass, sample_start, material, strategy, n_bsdf, m, run):
    """Every camera sample's slot numbers as the setup stage makes them: runs of ``run`` camera samples, 8 flat
    slots at a time, into rows (k - k0) m + j of a scratch, copied out to rows k m + j."""
    n = material.shape[0]
    out = np.full((n * m + 1, 3), -7.0)  # one row past the last camera sample's: must stay untouched
    own = np.full(((run * m + 7) // 8 * 8 + 1, 3), -9.0)
    for k0 in range(0, n, run):
        k1 = min(n, k0 + run)
        own[:] = -9.0
        for f in range(0, (k1 - k0) * m, LANES):
            mis = strategy == MIS
            slot_numbers_run(own, seed, pixels, spp_pass, sample_start, material, mis, n_bsdf, m, k0, k1 - k0, f)
        if own[(k1 - k0) * m :].max() != -9.0:  # no row past the run's is written
            out[-1] = 1e9
        for k in range(k0, k1):
            if material[k] >= 0:  # a loop, not a slice copy: Numba compiles the copy's shape checks for 1-2 s
                for j in range(m):
                    for d in range(3):
                        out[k * m + j, d] = own[(k - k0) * m + j, d]
    return out


@njit
def _scalar(seed, pixels, spp_pass, sample_start, material, strategy, n_bsdf, m):
    out = np.full((material.shape[0] * m + 1, 3), -7.0)
    for k in range(material.shape[0]):
        if material[k] < 0:
            continue
        rs = sample_state(SOBOL, seed, pixels[k // spp_pass], sample_start + k % spp_pass)
        for j in range(m):
            rj, slot = technique_slot(rs, strategy, n_bsdf, m - n_bsdf, j)
            u0, u1 = uniform_2d(rj, 2 + 3 * slot)
            out[k * m + j, 0] = u0
            out[k * m + j, 1] = u1
            out[k * m + j, 2] = uniform(rj, 4 + 3 * slot)
    return out


@pytest.mark.parametrize(
    ("strategy", "n_bsdf", "m", "spp_pass", "sample_start", "run"),
    [
        (MIS, 4, 8, 1, 0, 32),
        (MIS, 2, 3, 3, 5, 32),
        (MIS, 1, 2, 64, 1 << 20, 32),
        (MIS, 5, 13, 2, (1 << 32) - 1, 7),
        (MIS, 0, 4, 1, 0, 5),
        (BRDF, 1, 1, 4, 0, 32),
        (BRDF, 9, 9, 1, 0, 3),
    ],
)
def test_slot_numbers_in_lanes_are_the_scalar_samplers(strategy, n_bsdf, m, spp_pass, sample_start, run):
    """Slot j of camera sample k (pixel k // spp_pass, sample index sample_start + k % spp_pass, across 2^32 where a
    fresh scramble starts), runs whose slots do not fill whole blocks of 8, camera samples with nothing to shade
    (material -1: theirs are not needed), a pass whose length is not a multiple of the run."""
    rng = np.random.default_rng(m * 31 + n_bsdf)
    n = 1001 * spp_pass + 3
    pixels = rng.integers(0, 1 << 20, n // spp_pass + 1)
    material = np.where(rng.random(n) < 0.2, -1, rng.integers(0, 3, n))
    material[:40] = -1  # whole runs and blocks with nothing shaded
    seed = int(rng.integers(0, 1 << 31))
    lanes = _lanes(seed, pixels, spp_pass, sample_start, material, strategy, n_bsdf, m, run)
    scalar = _scalar(seed, pixels, spp_pass, sample_start, material, strategy, n_bsdf, m)
    assert np.array_equal(lanes, scalar)
    assert np.all(lanes[-1] == -7.0)
    shaded = np.repeat(material >= 0, m)
    assert np.all((lanes[:-1][shaded] >= 0.0) & (lanes[:-1][shaded] < 1.0))


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
