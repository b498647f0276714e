"""lightprobe against references it did not make: Mitsuba 3's images of the scenes of lightprobe.reference_scenes.

The convergence tests elsewhere compare lightprobe with itself, so a bias every strategy shares would pass them.
Here each strategy and light selector is z-tested per pixel against Mitsuba 3's ``direct`` integrator (the mean and
the variance of its mean, ``tests/data/mitsuba_<name>.npz``, made by ``benchmarks/mitsuba_references.py``; the
tests need no Mitsuba).  Per pixel and channel z = (ours - ref) / sqrt(var_ours + var_ref) (var_ours at least
Mitsuba's per-sample variance at our sample count, see the test): at most 1 % beyond 4,
none beyond 8, and pooled over the image (the sum of differences against the sum of variances) within 4 sigma per
channel, sigma at most 0.5 % of the image's sum: a bias of 2 % anywhere in the image, or of a fraction of a
percent everywhere, fails.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from lightprobe.integrators import outlines
from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.reference_scenes import NAMES, build

DATA = Path(__file__).resolve().parents[1] / "data"


def _reference(name):
    with np.load(DATA / f"mitsuba_{name}.npz") as f:
        return f["mean"].astype(np.float64), f["variance"].astype(np.float64), json.loads(str(f["settings"]))


CASES = [
    ("sky", {"strategy": "mis"}),
    ("sky", {"strategy": "mis", "sampler": "independent"}),
    ("sky", {"strategy": "env", "spp": 512}),
    ("area", {"strategy": "mis", "spp": 1024}),
    ("area", {"strategy": "mis", "light_sampler": "uniform", "spp": 1024}),
    ("area", {"strategy": "mis", "light_sampler": "bvh", "lights_per_sample": 2, "spp": 512}),
    ("area", {"strategy": "mis", "light_strategy": "area", "heuristic": "balance", "spp": 1024}),
    ("many", {"strategy": "mis", "light_sampler": "bvh", "spp": 1024}),
    ("many", {"strategy": "mis", "light_sampler": "power", "spp": 1024}),
    ("many", {"strategy": "mis", "light_sampler": "learned", "spp": 1024}),
    ("many", {"strategy": "env", "light_sampler": "uniform", "spp": 1024}),
    ("many-as-mesh", {"strategy": "mis", "light_sampler": "bvh", "spp": 1024}),
    ("sunsky", {"strategy": "mis"}),
    ("sunsky", {"strategy": "env", "spp": 512}),
]


def test_every_reference_is_present_and_quiet():
    """One reference per scene, far quieter than the renders judged against it (its relMSE floor, the mean of
    var / (mean^2 + 0.01), well under a 256-spp render's error) and finite everywhere."""
    for name in NAMES:
        mean, variance, settings = _reference(name)
        assert mean.shape == (48, 64, 3) and np.all(np.isfinite(mean)) and np.all(variance >= 0)
        assert settings["scene"] == name and settings["spp"] >= 16384
        assert np.mean(variance / (mean**2 + 0.01)) < 2e-3, name


def _outline_variance(scene) -> np.ndarray:
    """(H, W, 3) the variance of one camera sample's hits on the emitters' outlines: where an emitter of radiance L
    covers a share a of a pixel, a sample meets it with probability a, so its variance is at least about L^2 a (1 - a).
    A reference's own estimate misses it where none of its samples met a panel covering a hundred-thousandth of a
    pixel (the many-light scene: a mean of 0 and a variance of 0 at 65,536 spp, where lightprobe's outline control
    variate knows the exact L a, 0.001); integrators/outlines.py's table gives every such a."""
    table = outlines.table(scene.camera, scene.light_table(), None)
    w, h = scene.camera.resolution
    floor = np.zeros((w * h, 3))
    if table.start.size == 0:  # no emitter seen
        return floor.reshape(h, w, 3)
    pixels = np.repeat(np.arange(w * h), np.diff(table.start))
    radiance = table.radiance[table.shape]
    np.add.at(floor, pixels, radiance**2 * (table.cover * (1.0 - table.cover))[:, None])
    return floor.reshape(h, w, 3)


@pytest.mark.parametrize(
    ("scene", "options"), CASES, ids=lambda c: c if isinstance(c, str) else "-".join(map(str, c.values()))
)
def test_lightprobe_agrees_with_mitsuba(scene, options):
    name = scene.removesuffix("-as-mesh")
    assert_agrees_with_mitsuba(name, build(name, lights_as_mesh=scene.endswith("-as-mesh")), options)


def assert_agrees_with_mitsuba(name: str, built, options: dict, floor_with_reference: bool = True):
    """``built`` (the scene of ``tests/data/mitsuba_<name>.npz``) rendered with ``options`` passes the z-tests
    above; returns the render.  ``floor_with_reference`` False: our variance is our own estimate, not floored by
    Mitsuba's per-sample variance (for a scene where ours is far below Mitsuba's and no rare event hides)."""
    mean, variance, settings = _reference(name)
    options = {"spp": 256, "seed": 13, **options}
    ours = render(built, RenderSettings(**options))
    variance = np.maximum(variance, _outline_variance(built) / settings["spp"])
    # our variance, but never below what Mitsuba's samples show at our count: a rare bright event (a light smaller
    # than a pixel, a sun that BSDF samples seldom find) that none of our samples met leaves our estimate of the
    # variance far too low, and the pixel's z a false alarm
    ours_variance = ours.variance.astype(np.float64)
    if floor_with_reference:
        ours_variance = np.maximum(ours_variance, variance * settings["spp"] / options["spp"])
    # 2e-4 relative: float32 round-off where neither image has noise (a constant sky seen directly)
    z = (ours.image - mean) / np.sqrt(ours_variance + variance + (2e-4 * mean) ** 2 + 1e-12)
    assert np.mean(np.abs(z) > 4) < 0.01, np.sort(np.abs(z).ravel())[-5:]
    assert np.abs(z).max() < 8, np.sort(np.abs(z).ravel())[-5:]
    for c in range(3):
        difference = ours.image[..., c].sum() - mean[..., c].sum()
        sigma = math.sqrt(ours_variance[..., c].sum() + variance[..., c].sum())
        assert sigma < 5e-3 * mean[..., c].sum(), (c, sigma / mean[..., c].sum())
        assert abs(difference) < 4 * sigma, (c, difference / mean[..., c].sum(), difference / sigma)
    return ours


def test_the_many_light_scene_takes_a_count_of_lights():
    """The benchmarks' many-light scene is the test references' with more panels; a count elsewhere is an error."""
    from lightprobe.reference_scenes import MANY_LIGHTS, describe

    def emitters(desc):
        return sum("emission" in o for o in desc["objects"])

    assert emitters(describe("many")) == MANY_LIGHTS
    assert emitters(describe("many", lights=2000)) == 2000
    same, default = describe("many", lights=MANY_LIGHTS)["objects"], describe("many")["objects"]
    assert all(np.array_equal(a["origin"], b["origin"]) for a, b in zip(same[3:], default[3:], strict=True))
    for bad in ({"name": "area", "lights": 10}, {"name": "many", "lights": 0}):
        with pytest.raises(ValueError, match="lights="):
            describe(bad["name"], lights=bad["lights"])
