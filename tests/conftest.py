"""Shared fixtures.  Every random number in the suite comes from a fixed seed: tests never flake."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from lightprobe.data import data_dir
from lightprobe.errors import LightprobeWarning

DATA = data_dir()

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


@pytest.fixture(autouse=True)
def _fresh_warnings():
    """Each test hears every file warning anew (lightprobe warns once per file and process)."""
    from lightprobe import errors

    errors._warned.clear()
    yield
