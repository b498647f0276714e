"""Numba configuration shared by every compiled kernel.

All kernels are compiled with ``cache=True`` so that a second process loads machine code from disk instead of
recompiling.  Scalar kernels (one sample, returning tuples) are ``inline``-free ``njit`` functions; batch kernels
loop over samples and are the only ones marked ``parallel``.
"""

from __future__ import annotations

import os

# Numba's default OpenMP layer busy-waits between parallel regions, which slows down the Embree calls that
# run between our kernels (measured in ../shared/notes/raytracing-measurements.md).  The workqueue layer has no
# such spinning; it is also always available (TBB/OpenMP may not be).
os.environ.setdefault("NUMBA_THREADING_LAYER", "workqueue")

from numba import njit, prange

__all__ = ["jit", "jit_parallel", "prange"]


# Fast-math flags that keep IEEE semantics for NaN, infinities and signed zeros' meaning in comparisons:
# contraction into FMA, reciprocal approximations and approximate library functions.  'nnan'/'ninf' are left
# out on purpose: the renderer tests isfinite() to keep NaN and Inf out of images.
FASTMATH = {"contract", "arcp", "afn"}


def jit(func):
    """Compile a scalar or serial kernel (cached on disk)."""
    return njit(cache=True, nogil=True, error_model="numpy", fastmath=FASTMATH)(func)


def jit_parallel(func):
    """Compile a batch kernel that splits its ``prange`` loop over all cores (cached on disk)."""
    return njit(cache=True, nogil=True, parallel=True, error_model="numpy", fastmath=FASTMATH)(func)
