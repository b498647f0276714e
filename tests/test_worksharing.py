"""Work sharing (_worksharing.py): the chunks the workers claim cover a loop's items exactly once, and the render's
launcher (integrators/pipeline.Launcher) runs every item of a stage once with any number of workers."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from numba import njit

from lightprobe._worksharing import CHUNK, claim_range, new_counter


@njit(nogil=True)
def _visit(visits, owner, counter, worker):
    """Each item's visit count and the worker that visited it last, claimed as the stage loop claims its items."""
    n = visits.shape[0]
    lo, hi = claim_range(counter, n)
    while lo < hi:
        for i in range(lo, hi):
            visits[i] += 1
            owner[i] = worker
        lo, hi = claim_range(counter, n)


def _run(visits, owner, counter, workers):
    with ThreadPoolExecutor(workers) as pool:
        for f in [pool.submit(_visit, visits, owner, counter, w) for w in range(workers)]:
            f.result()


@pytest.mark.parametrize("n", [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 37 * CHUNK + 5])
@pytest.mark.parametrize("workers", [1, 2, 3])
def test_every_item_is_claimed_exactly_once(n, workers):
    visits, owner = np.zeros(n, np.int64), np.full(n, -1, np.int64)
    counter = new_counter()
    _run(visits, owner, counter, workers)
    assert np.all(visits == 1)
    assert np.all((owner >= 0) & (owner < workers))
    # the counter went past the last chunk once per worker (each worker's final, empty claim)
    assert counter[0] == -(-n // CHUNK) + workers


def test_a_used_counter_claims_nothing_until_reset():
    """The launcher zeroes the counter before each stage; one left as the last loop left it gives no chunk."""
    visits, owner = np.zeros(3 * CHUNK, np.int64), np.full(3 * CHUNK, -1, np.int64)
    counter = new_counter()
    _run(visits, owner, counter, 2)
    _run(visits, owner, counter, 2)
    assert np.all(visits == 1)
    counter[0] = 0
    _run(visits, owner, counter, 2)
    assert np.all(visits == 2)


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_the_launcher_runs_every_item_of_a_stage_once(workers):
    """The accumulation stage over 5,000 pixels x 3 samples: each pixel counted exactly 3 times, whatever the
    number of workers (more than the machine's cores included)."""
    from lightprobe.integrators import pipeline
    from lightprobe.integrators.accumulation import Accumulator

    from .integrators.stages import records

    pixels = np.random.default_rng(0).permutation(5000).astype(np.int64)
    c = records.constants(1, n_bsdf=0, pixels=pixels, spp_pass=3)
    recs = list(records.records(c, records.cameras(3 * pixels.size), records.slots(3 * pixels.size)))
    acc = Accumulator(pixels.size)
    recs[-1] = acc.arrays()
    pipeline.Launcher(workers).run(pipeline.stage_id("accumulate"), tuple(recs))
    assert np.all(acc.count == 3)


@njit(nogil=True)
def _mark(row, visits, owner, lo, hi):
    row[0] += 1  # this worker's own row: no other thread writes it
    for i in range(lo, hi):
        visits[i] += 1
        owner[i] = row[1]


def test_in_threads_covers_every_item_once_and_gives_each_worker_its_own_scratch_row():
    import numba

    from lightprobe._worksharing import in_threads

    threads = min(2, numba.config.NUMBA_NUM_THREADS)  # the suite's processes run one thread unless asked (conftest)
    n = 1024 * threads + 7  # enough items for every thread
    scratch = np.zeros((numba.config.NUMBA_NUM_THREADS, 2), np.int64)
    scratch[:, 1] = np.arange(scratch.shape[0])
    visits, owner = np.zeros(n, np.int64), np.full(n, -1, np.int64)
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        in_threads(_mark, n, visits, owner, scratch=scratch)
    finally:
        numba.set_num_threads(before)
    assert np.all(visits == 1)
    assert scratch[:threads, 0].tolist() == [1] * threads and not scratch[threads:, 0].any()
    assert sorted(set(owner.tolist())) == list(range(threads))  # each worker's items carry its own row's mark


def test_read_only_views_give_a_batch_kernel_one_signature_whatever_the_caller_passed():
    """A range kernel's inputs are read-only views however they come (a fresh array, a contiguous broadcast), so
    Numba compiles the kernel once (decisions.md 136): a material's and a map's batches see both kinds here."""
    from lightprobe._worksharing import read_only
    from lightprobe.bsdfs import GGXConductor, dispatch
    from lightprobe.emitters import envmap
    from lightprobe.emitters.procedural import constant

    a = np.arange(6.0).reshape(2, 3)
    view = read_only(a)
    assert not view.flags.writeable and np.shares_memory(view, a) and a.flags.writeable and read_only(view) is view
    wo = np.array([[0.0, 0.6, 0.8]])
    fresh = np.array([[0.3, 0.0, np.sqrt(0.91)]])
    shared = np.broadcast_to(fresh, (1, 3))  # contiguous and read-only: ascontiguousarray keeps it as it is
    assert not shared.flags.writeable and shared.flags.c_contiguous
    metal = GGXConductor(0.3, material="Al")
    values = [metal.eval(wo, wi) for wi in (fresh, shared)] + [metal.pdf(wo, wi) for wi in (fresh, shared)]
    np.testing.assert_array_equal(values[0], values[1])
    np.testing.assert_array_equal(values[2], values[3])
    sky = envmap.EnvironmentMap.from_array(constant(1.0, width=8, height=4))
    np.testing.assert_array_equal(sky.pdf(fresh), sky.pdf(shared))
    for kernel in (dispatch._eval_range, dispatch._pdf_range, envmap._pdf_range):
        assert len(kernel.signatures) == 1, (kernel.py_func.__name__, kernel.signatures)
