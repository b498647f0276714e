import mmap

import numpy as np

from lightprobe._memory import _HUGE_PAGE_THRESHOLD, fresh_array


def test_fresh_arrays_small_and_large_hold_what_is_written():
    for shape, dtype in (((10, 3), np.float64), ((_HUGE_PAGE_THRESHOLD // 4 + 1,), np.float32)):
        a = fresh_array(shape, dtype)
        assert a.shape == shape and a.dtype == dtype and a.flags.writeable
        a[...] = np.arange(a.size, dtype=dtype).reshape(shape)
        assert a.reshape(-1)[-1] == a.size - 1 and a.sum(dtype=np.float64) == a.size * (a.size - 1) / 2


def test_a_large_array_has_a_map_of_its_own():
    """Large arrays bypass NumPy's allocator (which would ask for transparent huge pages, decisions.md 32)."""

    def owner(a):
        while isinstance(a, np.ndarray) and a.base is not None:
            a = a.base
        return a.obj if isinstance(a, memoryview) else a

    large = fresh_array((_HUGE_PAGE_THRESHOLD // 8, 2))
    assert isinstance(owner(large), mmap.mmap) and not large.any()  # a fresh anonymous map is zeroed
    assert not isinstance(owner(fresh_array((4, 2))), mmap.mmap)
