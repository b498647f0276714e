"""Shared fixtures.  Every random number in the suite comes from a fixed seed: tests never flake."""

from __future__ import annotations

import ctypes
import os
import warnings

import numpy as np
import pytest

from lightprobe.data import data_dir
from lightprobe.errors import LightprobeWarning

DATA = data_dir()

# the suite's workers are one per core already: no compile helpers beside their renders (integrators/precompile.py)
os.environ["LIGHTPROBE_COMPILE_HELPERS"] = "0"


def _one_thread_a_worker() -> None:
    """Renders and batch kernels that do not name a thread count run on one thread in each test process.

    The workers are one process per core already, so a render's second thread shared a core with the other worker:
    4 threads on 2 cores, each stage of a pass waiting for its slowest thread (decisions.md 137: the render tests' CPU
    3 % less on one thread).  Tests that name their threads (the same bits on 1 and 2 threads, the ray tracer's and
    the work sharing's) still get them: ``numba.set_num_threads`` caps the count a caller may ask for only at
    ``NUMBA_NUM_THREADS``, which stays the machine's cores.  Subprocesses the tests start (the CLI's, Dask's workers)
    use every core, as a user's do."""
    import numba

    numba.set_num_threads(1)


_one_thread_a_worker()


def _keep_freed_memory_in_the_heap() -> None:
    """Ask glibc's malloc to keep 256 MB of freed memory at the top of its heap instead of giving it back.

    The suite's samplers allocate and free arrays of millions of numbers test after test; given back at each free,
    every new array is faulted in again, page by page (and NumPy's huge-page advice waits for compaction, decisions.md
    32): the BSDF chi-square tests spent 6.4 s in the kernel, 0.8 s with this (decisions.md 131).  This process is
    set here (glibc's ``mallopt``, M_TOP_PAD); the processes it starts read ``MALLOC_TOP_PAD_``.  Nothing the tests
    compute changes.
    """
    os.environ.setdefault("MALLOC_TOP_PAD_", str(256 << 20))
    try:
        ctypes.CDLL("libc.so.6").mallopt(-2, 256 << 20)  # M_TOP_PAD is -2 in glibc's malloc.h
    except (OSError, AttributeError):  # not glibc: nothing to tune
        pass


_keep_freed_memory_in_the_heap()

requires_data = pytest.mark.skipif(DATA is None, reason="../shared/data is absent (set LIGHTPROBE_DATA)")


def real_envmap_paths():
    """Every real map in the shared data folder (empty when it is absent)."""
    if DATA is None:
        return []
    return sorted(p for p in (DATA / "envmaps").iterdir() if p.suffix in (".exr", ".hdr"))


def load_quietly(path, **options):
    """Load a real map without the (expected) warning about clamped DWAB ringing."""
    from lightprobe.emitters.envmap import EnvironmentMap

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LightprobeWarning)
        return EnvironmentMap.load(path, **options)


def is_net(points) -> bool:
    """Whether n = len(points) points of the unit square (n a power of two) are a (0, m, 2)-net: every elementary
    interval of area 1/n (2^a x 2^b cells, a + b = log2 n) holds exactly one point."""
    n = len(points)
    m = n.bit_length() - 1
    assert n == 2**m, f"{n} points: not a power of two"
    for a in range(m + 1):
        cx = np.minimum((points[:, 0] * 2**a).astype(int), 2**a - 1)
        cy = np.minimum((points[:, 1] * 2 ** (m - a)).astype(int), 2 ** (m - a) - 1)
        if not np.all(np.bincount(cx * 2 ** (m - a) + cy, minlength=n) == 1):
            return False
    return True


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


# Files that open the suite on the two workers (pytest-xdist hands out files in this order, each to a worker that
# asks: in clean clones' runs one worker ran test_cli.py while the other ran the next three, decisions.md 137).  The
# render core compiles once, in about 100 s from an empty cache, and is then loaded from Numba's disk cache:
# test_cli.py renders in its first test, so one worker compiles the core at once while the other runs the core-free
# sampler and map tests; when both reached a render at the same moment both compiled it (decisions.md 89).
FIRST_FILES = (
    "tests/test_cli.py",
    "tests/bsdfs/test_bsdfs.py",
    "tests/geometry/test_scene_file.py",
    "tests/emitters/test_envmap.py",
)


def pytest_collection_modifyitems(config, items):
    """Order the files: FIRST_FILES first, then the others by their number of tests, most first (what
    pytest-xdist's own reordering does, turned off in pyproject.toml so that this order is kept); a file's tests
    keep their order.  Only the schedule changes: every test runs the same."""

    def file_of(item) -> str:  # as pytest-xdist names a file's scope: the node id's path
        return item.nodeid.split("::", 1)[0]

    counts: dict[str, int] = {}
    for item in items:
        counts[file_of(item)] = counts.get(file_of(item), 0) + 1

    def rank(item):
        name = file_of(item)
        if name in FIRST_FILES:
            return (0, FIRST_FILES.index(name), name)
        return (1, -counts[name], name)

    items.sort(key=rank)


@pytest.fixture(autouse=True)
def _fresh_warnings():
    """Each test hears every file warning anew (lightprobe warns once per file and process)."""
    from lightprobe import errors

    errors._warned.clear()
    yield
