"""Work sharing for the wavefront kernels: threads claim chunks of a loop from a shared counter.

Numba's ``prange`` on the workqueue layer (decisions.md 9) hands each thread one contiguous share of the iteration
space, fixed before the loop starts; ``numba.set_parallel_chunksize`` only cuts the shares finer, still assigned in
advance (decisions.md 28, 31).  Where the shares' costs differ -- the sky in one, the mesh in the other -- one
thread waits for the other at the end of every stage: the peer scene's stages kept both cores busy 87-96 % of their
time (decisions.md 57).  Here each thread runs one worker that claims the next chunk from an atomic counter until
none is left, so the threads finish together whatever the chunks cost.  Which thread computes an item changes from
run to run; what it computes does not (every item of a stage is independent, and per-thread scratch rows are
overwritten before use), so images stay bit-identical.

A kernel takes ``counter`` and ``workers`` (its last two parameters), loops ``for worker in prange(workers)``
(one worker per thread) and, inside, takes ``lo, hi = claim_range(counter, n)`` and its items ``range(lo, hi)``
while ``lo < hi``.  ``counter`` is an (8,) int64 array (one cache line) that must hold 0 when the kernel starts,
``workers`` the pool's thread count: ``wavefront._launch`` sets both before every launch; :func:`claims` gives a
fresh pair to a direct call.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ._numba import jit_inline

__all__ = ["CHUNK", "claim", "claim_range", "claims", "new_counter"]

#: items per claimed chunk (camera samples, slots or lanes blocks): thousands of chunks per pass, each tens of
#: microseconds, so the counter is touched rarely and the last chunk ends soon after the others
CHUNK = 512


def new_counter() -> np.ndarray:
    """A zeroed counter for :func:`claim` (reset it to 0 before each parallel loop that uses it)."""
    return np.zeros(8, np.int64)


@intrinsic
def claim(typingctx, counter):
    """Atomically add 1 to counter[0] and return the value before: the caller's chunk number.  (Relaxed ordering:
    the counter orders nothing but itself; the end of the parallel loop is the barrier that publishes the work.)"""
    if counter != types.Array(types.int64, 1, "C"):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        pointer = cgutils.get_item_pointer(context, builder, signature.args[0], array, [ir.Constant(ir.IntType(64), 0)])
        return builder.atomic_rmw("add", pointer, ir.Constant(ir.IntType(64), 1), "monotonic")

    return types.int64(counter), codegen


@jit_inline
def claim_range(counter, n):
    """The items [lo, hi) of the next unclaimed chunk of a loop over n items; lo >= hi once none is left."""
    lo = claim(counter) * CHUNK
    return lo, min(n, lo + CHUNK)


def claims() -> tuple[np.ndarray, int]:
    """(counter, workers) for a direct call of a work-sharing kernel: a zeroed counter, one worker per thread."""
    return new_counter(), numba.get_num_threads()
