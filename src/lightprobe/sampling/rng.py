"""The renderer's random numbers: u = f(seed, pixel, sample index, dimension), for two samplers.

Every random number of a render is a pure function of its coordinates, so an image does not depend on the order
in which samples are computed: any pass size, tile order or thread count gives the same bits, and a render split
into sample ranges merges exactly.

``independent``: a hash.  SplitMix64's finaliser (Steele et al. 2014) applied to a combination of the coordinates;
each value takes the top 53 bits as a double in [0, 1).

``sobol``: padded, Owen-scrambled Sobol' points (Burley, "Practical Hash-based Owen Scrambling", JCGT 2020, the
design of pbrt-v4's ``PaddedSobolSampler``).  The renderer's dimensions come in pairs (the pixel position, each
shading slot's 2D direction) and single decisions (lobe or light choice); each pair is its own 2D Sobol' sequence
(dimensions 0 and 1, a (0, 2)-sequence), its sample index shuffled per pixel and pair by a hash-based Owen
scramble of the index -- which maps the first 2^k indices onto one aligned block of 2^k points, so every
power-of-two prefix stays a stratified net -- and each coordinate Owen-scrambled with its own hash seed.  The
scrambles depend on (seed, pixel, dimension) only, so the numbers stay a pure function of the four coordinates.
"""

from __future__ import annotations

import numpy as np

from .._numba import jit, jit_inline, jit_parallel, prange

__all__ = [
    "SAMPLERS",
    "group_slot",
    "owen_scramble",
    "random_uniform",
    "sample_state",
    "sampler_batch",
    "sobol_2d",
    "uniform",
    "uniform_2d",
    "uniform_batch",
]

#: the samplers a render can use (settings ``sampler``)
SAMPLERS = {"independent": 0, "sobol": 1}
INDEPENDENT, SOBOL = 0, 1

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
_INV32 = 1.0 / 4294967296.0  # 2^-32
_U32 = np.uint64(0xFFFFFFFF)
_ONE = np.uint64(1)
_TOP = np.uint64(0x80000000)
_MASKS = (
    (np.uint64(1), np.uint64(0x55555555)),
    (np.uint64(2), np.uint64(0x33333333)),
    (np.uint64(4), np.uint64(0x0F0F0F0F)),
    (np.uint64(8), np.uint64(0x00FF00FF)),
)
_S16 = np.uint64(16)
_S32 = np.uint64(32)
# Vegdahl's improved Laine-Karras hash ("Building a better LK hash", 2021; pbrt-v4's FastOwenScrambler)
_LK1 = np.uint64(0x3D20ADEA)
_LK2 = np.uint64(0x05526C56)
_LK3 = np.uint64(0x53A22864)


@jit
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@jit
def pixel_key(seed, pixel):
    """A 64-bit key for one (seed, pixel)."""
    return _mix(np.uint64(seed) * _GOLDEN + np.uint64(pixel) * _PIXEL)


@jit
def sample_key(seed, pixel, sample):
    """A 64-bit key for one (seed, pixel, sample index); combine with :func:`random_uniform` per dimension."""
    return _mix(pixel_key(seed, pixel) + np.uint64(sample) * _GOLDEN)


@jit
def random_uniform(key, dim):
    """The ``dim``-th uniform number in [0, 1) of a sample key."""
    return float(_mix(key + np.uint64(dim) * _DIM + _GOLDEN) >> _S11) * _INV53


@jit
def _reverse32(x):
    for shift, mask in _MASKS:
        x = ((x >> shift) & mask) | ((x & mask) << shift)
    return ((x >> _S16) | (x << _S16)) & _U32


@jit
def _laine_karras(x, seed):
    """Vegdahl's Laine-Karras hash: each bit is flipped by a function of the seed and the bits *below* it."""
    x = (x ^ (x * _LK1)) & _U32
    x = (x + (seed & _U32)) & _U32
    x = (x * (((seed & _U32) >> _S16) | _ONE)) & _U32
    x = (x ^ (x * _LK2)) & _U32
    return (x ^ (x * _LK3)) & _U32


@jit
def owen_scramble(x, seed):
    """Hash-based Owen scrambling of a 32-bit value (Burley 2020, section 3): reversed, each bit flipped by a hash
    of the bits above it (in the original order), reversed back.  A bijection on [0, 2^32)."""
    return _reverse32(_laine_karras(_reverse32(x), seed))


# the superset sum of Sobol's second dimension (_sobol_y): (shift, positions whose bit of that weight is 0)
_SUPERSET = tuple((np.uint64(1 << q), np.uint64(m)) for q, m in enumerate(
    (0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF, 0x0000FFFF)))  # fmt: skip


@jit
def sobol_2d(index):
    """The first two dimensions of Sobol's sequence as 32-bit integers: van der Corput (bit reversal) and the
    Pascal-matrix generator (direction numbers v_{k+1} = v_k ^ (v_k >> 1))."""
    i = index & _U32
    return _reverse32(i), _sobol_y(i)


@jit
def _sobol_y(i):
    """Sobol's second dimension y = XOR of the direction numbers v_k of i's set bits k (v_0 = 2^31, v_{k+1} = v_k ^
    (v_k >> 1)).  Bit-reversed, v_k is (1 + x)^k, whose bit j is C(k, j) mod 2, odd exactly where j's bits are a
    subset of k's (Lucas's theorem); so reversed y's bit j is the XOR of i's bits k over the supersets k of j, a
    superset sum over GF(2) that five shift-and-xor steps compute (in place of four byte-table lookups)."""
    z = i & _U32
    for shift, mask in _SUPERSET:
        z ^= (z >> shift) & mask
    return _reverse32(z)


@jit
def _pair_of(dim):
    """The renderer's dimension layout (see ``integrators/techniques.py``): 0-1 the position in the pixel, then
    three per shading slot j -- 2 + 3j and 3 + 3j its 2D direction, 4 + 3j a 1D choice (BSDF lobe, light).
    Returns (Sobol' pair, coordinate): 2D decisions share a pair, a 1D choice gets a pair of its own."""
    if dim < 2:
        return 0, dim
    j, c = divmod(dim - 2, 3)
    if c < 2:
        return 1 + 2 * j, c
    return 2 + 2 * j, 0


@jit
def _pair_scramble(pkey, sample, pair):
    """One hash per (pixel, pair) -- its low 32 bits shuffle the sample index, its high 32 scramble x, and a second
    hash of it scrambles y -- and the shuffled index.  Sample indices of 2^32 and beyond (never reached in
    practice) start a fresh scramble."""
    h = _mix(pkey + np.uint64(pair + 1) * _DIM + (np.uint64(sample) >> _S32) * _GOLDEN)
    return h, owen_scramble(np.uint64(sample) & _U32, h)


@jit
def _sobol_x(h, index):
    # owen_scramble(reverse(index), h >> 32) without reversing twice
    return float(_reverse32(_laine_karras(index, h >> _S32))) * _INV32


@jit
def _sobol_y_scrambled(h, index):
    return float(owen_scramble(_sobol_y(index), _mix(h))) * _INV32


@jit
def sobol_uniform(pkey, sample, dim):
    """Dimension ``dim`` of sample ``sample`` of the padded Owen-scrambled Sobol' sampler in one pixel."""
    pair, c = _pair_of(dim)
    h, index = _pair_scramble(pkey, sample, pair)
    return _sobol_x(h, index) if c == 0 else _sobol_y_scrambled(h, index)


@jit
def sample_state(sampler, seed, pixel, sample):
    """Everything :func:`uniform` needs for one (seed, pixel, sample index) of ``sampler``."""
    pkey = pixel_key(seed, pixel)
    return sampler, _mix(pkey + np.uint64(sample) * _GOLDEN), pkey, sample


@jit
def uniform(state, dim):
    """The ``dim``-th uniform number in [0, 1) of a sample (``state`` from :func:`sample_state`)."""
    sampler, key, pkey, sample = state
    if sampler == SOBOL:
        return sobol_uniform(pkey, sample, dim)
    return random_uniform(key, dim)


@jit_inline
def uniform_2d(state, dim):
    """Dimensions ``dim`` and ``dim + 1`` of a sample, where ``dim`` begins a 2D pair of the layout (0, or 2 + 3j):
    the numbers two :func:`uniform` calls give, with the pair's hash and index shuffle computed once."""
    sampler, key, pkey, sample = state
    if sampler == SOBOL:
        pair, _ = _pair_of(dim)
        h, index = _pair_scramble(pkey, sample, pair)
        return _sobol_x(h, index), _sobol_y_scrambled(h, index)
    return random_uniform(key, dim), random_uniform(key, dim + 1)


@jit
def group_slot(state, first, n, j, spacing=1):
    """Shading sample j of a group of ``n`` slots that share a technique, the group's first slot being ``first``:
    the (state, slot) whose numbers it takes.  Under ``sobol`` the group shares the first slot's dimensions and
    sample k's j-th member takes sample index k n + j, so a pixel's first k samples give the group k n directions
    from one stratified Sobol' set (a (0, m, 2)-net whenever k n = 2^m) rather than n sets laid side by side without
    regard for one another; ``independent`` keeps a slot per member, ``first + j spacing``.  Either way a pure
    function of (seed, pixel, sample index, dimension)."""
    sampler, key, pkey, sample = state
    if sampler == SOBOL:
        return (sampler, key, pkey, sample * n + j), first
    return state, first + j * spacing


@jit_parallel
def sampler_batch(sampler, seed, pixels, samples, dims):
    """(N, dims) uniforms of ``sampler`` (a code of :data:`SAMPLERS`) for N (pixel, sample) pairs."""
    out = np.empty((pixels.shape[0], dims))
    for i in prange(pixels.shape[0]):
        state = sample_state(sampler, seed, pixels[i], samples[i])
        for d in range(dims):
            out[i, d] = uniform(state, d)
    return out


@jit_parallel
def uniform_batch(seed, pixels, samples, dims):
    """(N, dims) uniforms for N (pixel, sample) pairs: for tests and NumPy users."""
    out = np.empty((pixels.shape[0], dims))
    for i in prange(pixels.shape[0]):
        key = sample_key(seed, pixels[i], samples[i])
        for d in range(dims):
            out[i, d] = random_uniform(key, d)
    return out
