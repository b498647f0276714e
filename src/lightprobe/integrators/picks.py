"""How many lights a camera sample picks (K), chosen per scene by a probe where the scene has many lights.

Decision 122 measured that no one K suits every scene of 64 bounded lights or more: in a building whose lights are
mostly behind walls, each doubling of K lowers the error 3-4x (K = 16: 4.5x the efficiency of K = 4 at 16 spp),
while on a dome of lights or a city K = 16 loses 40-50 %.  So where K is left automatic in such a scene, and the
render is long enough to pay for it (``PROBE_SHARE``), a probe renders a lattice of about ``PROBE_PIXELS`` of the
image's pixels (at the image's own resolution: a coarser image has larger pixel footprints, whose variance hides
the light choice's) at ``PROBE_SPP`` samples, twice with fixed seeds, for each K of ``CANDIDATES``.  Each K's error
is the relMSE between its two images (the difference of two independent estimates: unlike the accumulator's
var / n it sees how a pixel's Sobol' samples stratify together), its cost ``1 + PICK_COST K`` per camera sample
(the time per extra pick measured in decision 122); the K of the highest 1 / (error x cost) wins (decisions.md
123).  No clock enters the choice: it is a function of the scene and the settings other than the seed, the sample
range and the time limit, so a resumed render, a sample range and a chunked reference choose the same K (and the
reference and Dask drivers resolve it once, :func:`lightprobe.integrators.wavefront.settings_for`).

This module holds the probe's rules; the driver (integrators/wavefront.py) renders it.
"""

from __future__ import annotations

import math

import numpy as np

from .light_learning import UNIFORM_PILOT
from .settings import MANY_LIGHTS, MANY_LIGHTS_PICKS, MAX_SLOTS, RenderSettings

__all__ = [
    "CANDIDATES",
    "PROBE_SEEDS",
    "PROBE_SHARE",
    "PROBE_SPP",
    "candidates",
    "chosen",
    "cost",
    "probe_pixels",
    "probe_samples",
    "probes",
    "relmse",
]

CANDIDATES = (4, 8, 16)  # MANY_LIGHTS_PICKS first: the choice when the probe tells nothing apart
PROBE_SPP = 8  # per pixel and seed, picking with the light selection learned once before (wavefront._probed)
PROBE_PIXELS = 1024
PROBE_SEEDS = (7_919, 104_729)  # fixed: every seed of a render chooses the same K
# a render whose light samples (to its range's end, at MANY_LIGHTS_PICKS) are fewer than the probe's over this
# share keeps MANY_LIGHTS_PICKS: at 16 spp and 320 x 240 the probe cost the ceiling 9 % and the city 13 % of their
# efficiency (decisions.md 123)
PROBE_SHARE = 0.05
PICK_COST = 0.55  # the time of an extra pick, as a share of a camera sample's time with none (decisions.md 122)


def probes(scene, settings: RenderSettings, resolved: RenderSettings) -> bool:
    """Whether a render of ``scene`` with ``settings`` (as given; ``resolved``: with the automatic choices made)
    chooses its K by the probe: K left automatic and resolved to the many-light choice, light samples taken, room
    in a camera sample's slots for K = 8, and a render whose light samples at that choice, to its range's end, are
    at least the probe's over ``PROBE_SHARE``: at 320 x 240, from 34 spp; at 640 x 480, from 9 (a render of
    fewer pays the probe more than it can expect back, and an image of a few pixels never probes)."""
    if not (
        settings.lights_per_sample is None
        and resolved.lights_per_sample == MANY_LIGHTS_PICKS
        and scene.bounded_light_count >= MANY_LIGHTS
        and resolved.strategy in ("mis", "env")
        and resolved.n_env >= 1
        and len(candidates(resolved)) > 1
    ):
        return False
    width, height = scene.camera.resolution
    light_samples = width * height * (settings.first_sample + settings.spp) * MANY_LIGHTS_PICKS * resolved.n_env
    return light_samples * PROBE_SHARE >= probe_samples(width, height, resolved)


def candidates(resolved: RenderSettings) -> tuple[int, ...]:
    """The K of ``CANDIDATES`` whose slots (n_bsdf + K n_env) fit in a camera sample's ``MAX_SLOTS``."""
    return tuple(k for k in CANDIDATES if resolved.n_bsdf + k * resolved.n_env <= MAX_SLOTS)


def probe_samples(width: int, height: int, resolved: RenderSettings) -> int:
    """The light samples the probe of an image of ``width`` x ``height`` takes: the learning pilot's
    (``UNIFORM_PILOT`` samples at the largest K) and ``PROBE_SPP`` samples per seed at every candidate K."""
    ks = candidates(resolved)
    per_pixel = UNIFORM_PILOT * max(ks) + PROBE_SPP * len(PROBE_SEEDS) * sum(ks)
    return probe_pixels(width, height)[0].size * per_pixel * resolved.n_env


def probe_pixels(width: int, height: int) -> tuple[np.ndarray, int]:
    """(the probe's pixel indices, their stride): every ``stride``-th pixel in raster order, about
    ``PROBE_PIXELS`` of them (all of a smaller image), the stride prime to the width so that successive rows take
    different columns (a lattice over the image, not a few vertical stripes)."""
    n = width * height
    stride = max(1, n // PROBE_PIXELS)
    while stride > 1 and math.gcd(stride, width) != 1:
        stride += 1
    return np.arange(0, n, stride, dtype=np.int64), stride


def relmse(a: np.ndarray, b: np.ndarray) -> float:
    """The relMSE of one image of two independent renders ``a`` and ``b`` (pixels x 3) of the same scene: half
    their squared difference (the variance of either) over (their mean squared + 0.01), averaged."""
    mean = 0.5 * (a + b)
    return float(np.mean(0.5 * (a - b) ** 2 / (mean * mean + 0.01)))


def cost(k: int) -> float:
    """A camera sample's time with ``k`` picks, in units of its time with none (decisions.md 122's fit)."""
    return 1.0 + PICK_COST * k


def chosen(errors: dict[int, float]) -> int:
    """The K of ``errors`` (K -> relMSE of the probe) of highest efficiency 1 / (relMSE x cost); the first of them
    (MANY_LIGHTS_PICKS) where the errors are zero or not finite (a black or broken probe tells nothing)."""
    ks = list(errors)
    if not all(math.isfinite(e) and e > 0.0 for e in errors.values()):
        return ks[0]
    return min(ks, key=lambda k: errors[k] * cost(k))
