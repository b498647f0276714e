"""The peer kit's helpers that need no kit (lightprobe/peer.py)."""

from __future__ import annotations

import numpy as np

from lightprobe.images import write_image
from lightprobe.peer import reference_floor


def test_reference_floor_is_the_kits_ref_floor(tmp_path):
    """mean over pixels and channels of var / (ref^2 + 0.01), from NAME_var.exr beside NAME.exr; None without it."""
    rng = np.random.default_rng(0)
    ref = rng.uniform(0.0, 3.0, (6, 8, 3)).astype(np.float32)
    var = rng.uniform(0.0, 1e-3, (6, 8, 3)).astype(np.float32)
    write_image(str(tmp_path / "ref.exr"), ref)
    assert reference_floor(tmp_path / "ref.exr") is None
    write_image(str(tmp_path / "ref_var.exr"), var)
    expected = np.mean(var.astype(np.float64) / (ref.astype(np.float64) ** 2 + 0.01))
    assert np.isclose(reference_floor(str(tmp_path / "ref.exr")), expected, rtol=1e-6)  # float32 images
