"""Work sharing (_worksharing.py): the chunks the threads claim cover a loop's items exactly once."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from lightprobe._numba import jit_parallel, prange
from lightprobe._worksharing import CHUNK, claim_range, claims


@jit_parallel
def _visit(visits, owner, counter, workers):
    """Each item's visit count and the worker that visited it last, claimed as the kernels claim theirs."""
    n = visits.shape[0]
    for worker in prange(workers):
        lo, hi = claim_range(counter, n)
        while lo < hi:
            for i in range(lo, hi):
                visits[i] += 1
                owner[i] = worker
            lo, hi = claim_range(counter, n)


@pytest.mark.parametrize("n", [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 37 * CHUNK + 5])
@pytest.mark.parametrize("threads", [1, 2])
def test_every_item_is_claimed_exactly_once(n, threads):
    previous = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        visits, owner = np.zeros(n, np.int64), np.full(n, -1, np.int64)
        counter, workers = claims()
        _visit(visits, owner, counter, workers)
    finally:
        numba.set_num_threads(previous)
    assert np.all(visits == 1)
    assert np.all((owner >= 0) & (owner < workers))
    # the counter went past the last chunk once per worker (each worker's final, empty claim)
    assert counter[0] == -(-n // CHUNK) + workers


def test_a_used_counter_claims_nothing_until_reset():
    """The launcher zeroes the counter before each kernel; one left as the last loop left it gives no chunk."""
    visits, owner = np.zeros(3 * CHUNK, np.int64), np.full(3 * CHUNK, -1, np.int64)
    counter, workers = claims()
    _visit(visits, owner, counter, workers)
    _visit(visits, owner, counter, workers)
    assert np.all(visits == 1)
    counter[0] = 0
    _visit(visits, owner, counter, workers)
    assert np.all(visits == 2)
