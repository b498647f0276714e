"""Large arrays without transparent huge pages.

NumPy asks the kernel for transparent huge pages (``madvise``) on every allocation of 4 MB or more.  With the common
``defrag = madvise`` setting, the first touch of each such page then waits for the kernel to compact memory, which
takes long when memory is fragmented (as it is after a while on a busy machine).  Measured on the 2-core VM:
first-touching a 268 MB table took 0.8 s, 0.13 s in a plain anonymous map; a peer-scene render's first two passes,
which touch its 330 MB of fresh pass buffers, took 0.51-0.62 s each against 0.20-0.28 s for the later ones, and
0.25-0.28 s with the buffers mapped like this (decisions.md 22 and 32).  Pages of an anonymous map come from the
kernel zeroed, four kilobytes at a time; later passes run at the same speed either way.

The map is populated when it is made (``MAP_POPULATE``): one call maps every page, where first touches took a page
fault each (1 GB on a fresh VM: 1.9 s touched page by page, 0.29 s populated; but populating took up to 2.3 s a GB
where the host had not backed the memory yet).  A render's pass buffers are made before its clock starts, so that
time is setup, not part of a render's first passes (decisions.md 39).
"""

from __future__ import annotations

import mmap

import numpy as np

__all__ = ["fresh_array"]

_HUGE_PAGE_THRESHOLD = 1 << 22  # NumPy's: smaller allocations are not madvised
# MAP_POPULATE: the kernel maps (and zeroes) every page when the map is made, in one call, instead of one page fault
# per 4 KB page at first touch (Linux; elsewhere the pages come at first touch, as before)
_POPULATE = getattr(mmap, "MAP_POPULATE", 0)


def _anonymous_map(nbytes: int) -> mmap.mmap:
    if _POPULATE:
        return mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | _POPULATE)
    return mmap.mmap(-1, nbytes)


def fresh_array(shape, dtype=np.float64) -> np.ndarray:
    """An array of ``shape`` (contents unspecified), in its own anonymous memory map when NumPy would ask for huge
    pages.  The map is released with the last view of it."""
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    if nbytes < _HUGE_PAGE_THRESHOLD:
        return np.empty(shape, dtype)
    return np.frombuffer(_anonymous_map(nbytes), dtype=dtype).reshape(shape)
