"""The order of a pass's pixels: a permutation of the band that gives every thread's share work from all of it."""

import numpy as np
import pytest

from lightprobe.integrators.schedule import BLOCK, pass_pixels


@pytest.mark.parametrize("count", [1, 7, BLOCK, 3 * BLOCK, 3 * BLOCK + 5, 256 * BLOCK, 257 * BLOCK - 1])
def test_every_pixel_of_the_band_appears_once(count):
    first = 12345
    order = pass_pixels(first, count)
    assert order.dtype == np.int64
    assert np.array_equal(np.sort(order), np.arange(first, first + count))


def test_a_small_band_keeps_image_order():
    assert np.array_equal(pass_pixels(10, 2 * BLOCK + 3), np.arange(10, 10 + 2 * BLOCK + 3))


@pytest.mark.parametrize("threads", [2, 3, 4])
def test_each_threads_share_spans_the_band(threads):
    # prange gives thread t the t-th contiguous share of the buffer; each share must take pixels from every part
    # of the band (here: each quarter holds between 1/2 and 3/2 of its fair part of every share)
    count = 256 * BLOCK
    order = pass_pixels(0, count)
    for share in np.array_split(order, threads):
        quarters = np.bincount(share * 4 // count, minlength=4)
        fair = share.size / 4
        assert quarters.min() >= 0.5 * fair and quarters.max() <= 1.5 * fair


def test_blocks_stay_runs_of_consecutive_pixels():
    order = pass_pixels(0, 16 * BLOCK)
    runs = order.reshape(-1, BLOCK)
    assert np.all(np.diff(runs, axis=1) == 1)
    assert not np.array_equal(order, np.arange(order.size))  # and the blocks are reordered
