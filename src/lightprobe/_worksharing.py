"""Work sharing for the render's stages: workers claim chunks of a loop from a shared counter.

A fixed share per thread, as Numba's ``prange`` hands out (``numba.set_parallel_chunksize`` only cuts the shares
finer, still assigned in advance: decisions.md 28, 31), leaves one thread waiting for the other at the end of every
stage where the shares' costs differ -- the sky in one, the mesh in the other: the peer scene's stages kept both
cores busy 87-96 % of their time (decisions.md 57).  Here each worker claims the next chunk from an atomic counter
until none is left, so the workers finish together whatever the chunks cost.  Which worker computes an item changes
from run to run; what it computes does not (every item of a stage is independent, and per-worker scratch rows are
overwritten before use), so images stay bit-identical.

A loop takes ``lo, hi = claim_range(counter, n)`` and its items ``range(lo, hi)`` while ``lo < hi``; ``counter`` is
an (8,) int64 array (one cache line) that holds 0 when the loop starts.  The render's stage loop
(``integrators/pipeline.run_stage``) is its user.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor, wait

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ._numba import jit_inline

__all__ = [
    "CHUNK",
    "COUNTER_TYPE",
    "claim",
    "claim_range",
    "in_threads",
    "new_counter",
    "on_workers",
    "read_only",
    "read_only_rows",
]

#: items per claimed chunk (camera samples, slots or lanes blocks): thousands of chunks per pass, each tens of
#: microseconds, so the counter is touched rarely and the last chunk ends soon after the others
CHUNK = 512


#: the counter's Numba type
COUNTER_TYPE = types.Array(types.int64, 1, "C")


def new_counter() -> np.ndarray:
    """A zeroed counter for :func:`claim` (reset it to 0 before each loop that uses it)."""
    return np.zeros(8, np.int64)


@intrinsic
def claim(typingctx, counter):
    """Atomically add 1 to counter[0] and return the value before: the caller's chunk number.  (Relaxed ordering:
    the counter orders nothing but itself; the launcher's wait for every worker at the end of a stage publishes
    the work.)"""
    if counter != COUNTER_TYPE:
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


_POOL: list[ThreadPoolExecutor] = []  # the worker threads beside the calling one, made on first use


def on_workers(task, workers: int) -> None:
    """``task(w)`` for each worker ``w`` of ``workers``: worker 0 is the calling thread, the others a shared pool's
    threads (grown when more are asked for), so tasks that release the GIL run in parallel.  Every worker is waited
    for, even after an error or a Ctrl-C in the calling thread (none is left writing into its arrays), and the first
    error is raised then."""
    futures = []
    if workers > 1:
        if not _POOL or _POOL[0]._max_workers < workers - 1:
            _POOL[:] = [ThreadPoolExecutor(max_workers=workers - 1, thread_name_prefix="lightprobe-worker")]
        futures = [_POOL[0].submit(task, w) for w in range(1, workers)]
    try:
        task(0)
    finally:
        wait(futures)
    for future in futures:
        future.result()


def in_threads(kernel, n: int, *args, scratch=None) -> None:
    """``kernel(*args, lo, hi)`` over the items [0, n), split among Numba's threads (:func:`on_workers`): a serial
    kernel (it releases the GIL) over independent items, called from threads instead of compiled as a ``prange``
    loop.  Numba's parallel-loop passes made such loops slow to compile: the ray tracer's batches 5.3-5.4 s each,
    their range kernels 1.7-1.8 s, at the same speed (decisions.md 129).  Items are independent, so any split gives
    the same bits; below 1,024 items a split is not worth a thread.  ``scratch`` (one row per thread, at least
    ``numba.get_num_threads()`` rows): worker w's row is passed first, ``kernel(scratch[w], *args, lo, hi)``."""
    threads = max(1, min(numba.get_num_threads(), n // 1024))
    bounds = [n * k // threads for k in range(threads + 1)]
    if scratch is None:
        on_workers(lambda w: kernel(*args, bounds[w], bounds[w + 1]), threads)
    else:
        on_workers(lambda w: kernel(scratch[w], *args, bounds[w], bounds[w + 1]), threads)


def read_only(a: np.ndarray) -> np.ndarray:
    """``a`` as a read-only view (``a`` itself when it is one): a range kernel's inputs of one array type however the
    caller made them (a broadcast view is read-only, a fresh array writable), so that Numba compiles the kernel once
    and not a second time for the other kind (1.3 s for a material's eval batch, 2.8-3.0 s for the light
    selector's; decisions.md 136)."""
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


def read_only_rows(x, n: int) -> np.ndarray:
    """(n, 3) float64, C order, read-only (:func:`read_only`): one row given for all n, or n rows of their own (any
    leading shape): the points, normals or directions a range kernel reads, as one array type."""
    a = np.asarray(x, dtype=np.float64)
    return read_only(np.ascontiguousarray(np.broadcast_to(a.reshape(-1, 3) if a.ndim > 1 else a, (n, 3))))
