"""Counter-based random numbers: u = hash(seed, pixel, sample index, dimension).

Every random number of a render is a pure function of its coordinates, so an image does not depend on the order
in which samples are computed: any pass size, tile order or thread count gives the same bits.  The hash is
SplitMix64's finaliser (Steele et al. 2014) applied to a combination of the coordinates; each value takes the top
53 bits as a double in [0, 1).
"""

from __future__ import annotations

import numpy as np

from .._numba import jit, jit_parallel, prange

__all__ = ["random_uniform", "uniform_batch"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_PIXEL = np.uint64(0xD1342543DE82EF95)
_DIM = np.uint64(0xAF251AF3B0F025B5)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0  # 2^-53


@jit
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@jit
def sample_key(seed, pixel, sample):
    """A 64-bit key for one (seed, pixel, sample index); combine with :func:`random_uniform` per dimension."""
    k = _mix(np.uint64(seed) * _GOLDEN + np.uint64(pixel) * _PIXEL)
    return _mix(k + np.uint64(sample) * _GOLDEN)


@jit
def random_uniform(key, dim):
    """The ``dim``-th uniform number in [0, 1) of a sample key."""
    return float(_mix(key + np.uint64(dim) * _DIM + _GOLDEN) >> _S11) * _INV53


@jit_parallel
def uniform_batch(seed, pixels, samples, dims):
    """(N, dims) uniforms for N (pixel, sample) pairs: for tests and NumPy users."""
    out = np.empty((pixels.shape[0], dims))
    for i in prange(pixels.shape[0]):
        key = sample_key(seed, pixels[i], samples[i])
        for d in range(dims):
            out[i, d] = random_uniform(key, d)
    return out
