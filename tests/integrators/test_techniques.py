"""The renderer's shading slots hand their sampler's 2D pair to the BSDF as its direction."""

from __future__ import annotations

import numpy as np

from lightprobe.bsdfs import Lambert
from lightprobe.integrators.techniques import BRDF, COSINE, SLOT_BSDF, SLOT_HEMI, sample_direction
from lightprobe.sampling.kernels import cosine_hemisphere_to_square
from lightprobe.sampling.rng import SAMPLERS, sample_state, uniform

WO = (0.3, -0.2, np.sqrt(1.0 - 0.13))


def _slot_points(technique, n=256, slot=1, pixel=7):
    """The unit-square points behind n directions of one slot of one pixel, from the renderer's Sobol' sampler."""
    bsdf = Lambert(0.5)
    points = np.empty((n, 2))
    for i in range(n):
        rs = sample_state(SAMPLERS["sobol"], 3, pixel, i)
        u0, u1, u2 = (uniform(rs, 2 + 3 * slot + c) for c in range(3))
        state, wi, pdf, _ = sample_direction(technique, bsdf.kind, bsdf.params, WO, u0, u1, u2)
        assert state == (SLOT_BSDF if technique == BRDF else SLOT_HEMI) and pdf > 0.0
        points[i] = cosine_hemisphere_to_square(*wi)
    return points


def _is_net(points, n=256):
    """Every elementary interval of area 1/n (2^a x 2^b cells, a + b = log2 n) holds exactly one point."""
    m = int(np.log2(n))
    for a in range(m + 1):
        cx = np.minimum((points[:, 0] * 2**a).astype(int), 2**a - 1)
        cy = np.minimum((points[:, 1] * 2 ** (m - a)).astype(int), 2 ** (m - a) - 1)
        counts = np.bincount(cx * 2 ** (m - a) + cy, minlength=n)
        if not np.all(counts == 1):
            return False
    return True


def test_bsdf_directions_come_from_the_slots_2d_pair():
    # cosine-hemisphere sampling inverts exactly, so a Lambertian's sampled directions map back to the numbers
    # that made them; from a (0, 2)-sequence pair those form a (0, 8, 2)-net.  A lobe choice taken from the pair
    # (the layout before issue 9's fix) mixes two pairs and breaks it.
    assert _is_net(_slot_points(BRDF))
    assert _is_net(_slot_points(COSINE))


def test_the_net_check_can_fail():
    rng = np.random.default_rng(1)
    assert not _is_net(rng.random((256, 2)))
    mixed = _slot_points(BRDF)
    mixed[:, 1] = _slot_points(BRDF, slot=2)[:, 1]  # coordinates of two different pairs
    assert not _is_net(mixed)
