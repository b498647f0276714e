"""The order of a pass's pixels in its buffers: blocks of pixels spread over the band, so that threads share work.

Numba's ``prange`` gives each thread one contiguous share of a loop's range, and every kernel of a pass loops over
the pass's buffers, whose entries follow the pass's pixels.  Work is not spread evenly over the image: the sky at
the top of the frame costs a camera ray and nothing else, the ground and the objects below it cost every shading
stage (peer scene: 40 % of a pass's live shading slots in its first half, 60 % in its second).  In image order,
the thread given the top of the frame idled while the other finished.  So a pass lists its pixels in blocks of ``BLOCK``
consecutive pixels, taken in the order (b x stride) mod blocks, the stride coprime to the number of blocks and
near blocks / golden ratio: every pixel appears once, and any run of consecutive blocks -- each thread's share --
is spread over the whole band (a Kronecker sequence).  A pixel's samples keep their random numbers (they depend on
the pixel and sample index, not on the position in the buffer) and are accumulated in sample order, so the order
changes no bit of the image.  Measurements: decisions.md 31.  (Since decisions.md 57 the kernels also claim their
range in chunks as they go, `_worksharing.py`, which evens out what a fixed share would leave uneven.)
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

__all__ = ["BLOCK", "pass_pixels", "spread"]

BLOCK = 1024  # consecutive pixels kept together (coherent camera rays); a 512^2 pass still has 256 blocks


def _stride(blocks: int) -> int:
    """Coprime to ``blocks``, near blocks x (1 - 1 / golden ratio)."""
    stride = max(1, int(blocks * 0.3819660112501051))
    while math.gcd(stride, blocks) != 1:
        stride += 1
    return stride


@lru_cache(maxsize=4)
def _offsets(count: int) -> np.ndarray:
    order = np.arange(count, dtype=np.int64)
    blocks = count // BLOCK
    if blocks >= 3:
        starts = (np.arange(blocks, dtype=np.int64) * _stride(blocks)) % blocks * BLOCK
        order[: blocks * BLOCK] = (starts[:, None] + np.arange(BLOCK)).ravel()
    order.flags.writeable = False
    return order


def pass_pixels(first: int, count: int) -> np.ndarray:
    """The pixels first .. first + count - 1 of a pass, in the order their samples sit in the pass's buffers
    (int64).  Pixels after the last full block keep their places."""
    return first + _offsets(count)


def spread(pixels: np.ndarray) -> np.ndarray:
    """Any list of pixels (an adaptive round's) in the same spread-out block order."""
    return pixels[_offsets(pixels.size)]
