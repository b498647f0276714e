"""The light picks a probe chooses (integrators/picks.py, decisions.md 123): its rules, and renders that run it.

The probe's threshold (``PROBE_SHARE``) keeps it out of renders as small as the tests'; the renders here raise the
threshold so that a 32 x 24 image probes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.integrators import picks
from lightprobe.integrators.settings import MANY_LIGHTS_PICKS
from lightprobe.integrators.wavefront import RenderSettings, render, settings_for
from lightprobe.reference_scenes import build

from .test_wavefront import assert_the_same_bits_on_any_threads_and_pass_size


@pytest.fixture(scope="module")
def building():
    return build("building", resolution=(32, 24))


@pytest.fixture
def probing(monkeypatch):
    """Every render of many lights long enough for any probe probes (the threshold raised out of the way)."""
    monkeypatch.setattr(picks, "PROBE_SHARE", 1e9)


def test_the_k_of_least_error_times_cost_is_chosen_and_ties_keep_the_first():
    assert picks.cost(8) > picks.cost(4) > 1.0
    errors = {4: 0.01, 8: 0.004, 16: 0.003}
    assert picks.chosen(errors) == min(errors, key=lambda k: errors[k] * picks.cost(k)) == 8
    assert picks.chosen({4: 0.01, 8: 0.01 * picks.cost(4) / picks.cost(8)}) == 4  # a tie keeps MANY_LIGHTS_PICKS
    assert picks.chosen({4: 0.01, 8: 0.02, 16: 0.0001}) == 16
    assert picks.chosen({4: 0.0, 8: 0.0, 16: 0.0}) == 4  # a black probe tells nothing
    assert picks.chosen({4: 0.01, 8: math.nan, 16: 0.001}) == 4


def test_the_probe_error_is_the_variance_of_one_image_over_the_mean_squared():
    rng = np.random.default_rng(3)
    a = rng.uniform(0.5, 2.0, (1000, 3))
    assert picks.relmse(a, a) == 0.0
    b = a + 0.2
    expected = np.mean(0.5 * 0.04 / ((a + 0.1) ** 2 + 0.01))
    assert picks.relmse(a, b) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("size", [(320, 240), (640, 480), (1920, 1080), (33, 17), (8, 5)])
def test_the_probe_pixels_are_a_lattice_over_the_whole_image(size):
    width, height = size
    pixels, stride = picks.probe_pixels(width, height)
    n = width * height
    np.testing.assert_array_equal(pixels, np.arange(0, n, stride))
    if n <= picks.PROBE_PIXELS:
        assert stride == 1 and pixels.size == n
        return
    assert math.gcd(stride, width) == 1
    assert 0.9 * picks.PROBE_PIXELS <= pixels.size <= picks.PROBE_PIXELS + 1
    rows, columns = np.divmod(pixels, width)
    # every eighth of the image's height and of its width holds some of them: no stripes, no band left out
    assert np.unique(rows * 8 // height).size == 8 and np.unique(columns * 8 // width).size == 8


def test_only_long_automatic_renders_of_many_lights_probe():
    dome, area = build("dome", resolution=(320, 240)), build("area", resolution=(320, 240))

    def probes(scene, **options):
        settings = RenderSettings(**options)
        short = RenderSettings(**{**options, "spp": 1, "first_sample": 0})  # resolved as without the probe
        return picks.probes(scene, settings, settings_for(scene, short))

    assert probes(dome, spp=64) and probes(dome, spp=256) and probes(dome, spp=16, first_sample=48)
    assert not probes(dome, spp=16)  # the probe would be over PROBE_SHARE of the render
    assert not probes(dome, spp=64, lights_per_sample=4)  # K given
    assert not probes(dome, spp=64, strategy="brdf")  # no light samples
    assert probes(dome, spp=64, n_env=7) and not probes(dome, spp=64, n_env=8)  # 1 + 8 x 8 > 64 slots: K = 4 alone
    assert not probes(area, spp=256)  # 18 bounded lights: K = 2 (decision 97)
    assert not probes(build("dome", resolution=(32, 24)), spp=1024)  # a few pixels: the probe would cost too much
    assert probes(build("dome", resolution=(640, 480)), spp=16)


def test_a_probed_render_is_the_render_with_its_chosen_k(building, probing):
    settings = RenderSettings(spp=12, seed=4)
    probed = render(building, settings)
    probe = probed.stats["picks_probe"]
    k = probed.stats["lights_per_sample"]
    assert k == probe["chosen"] == picks.chosen({int(key): e for key, e in probe["relmse"].items()})
    assert list(probe["relmse"]) == ["4", "8", "16"] and probe["pixels"] == 32 * 24
    assert 0.0 < probe["seconds"] <= probed.stats["seconds"]  # the render's time includes its probe's
    explicit = render(building, RenderSettings(spp=12, seed=4, lights_per_sample=k))
    assert "picks_probe" not in explicit.stats
    np.testing.assert_array_equal(probed.image, explicit.image)
    np.testing.assert_array_equal(probed.variance, explicit.variance)
    assert settings_for(building, settings).lights_per_sample == k
    # the probe sees the building's hidden lights: more picks there than on a dome of lights facing the objects
    dome = render(build("dome", resolution=(32, 24)), settings).stats
    assert k > MANY_LIGHTS_PICKS == dome["lights_per_sample"] == dome["picks_probe"]["chosen"]
    # another seed, the same choice: the probe's seeds are its own
    assert render(building, RenderSettings(spp=12, seed=9)).stats["lights_per_sample"] == k


def test_a_probed_render_is_the_same_bits_on_any_threads_and_pass_size(building, probing):
    base = assert_the_same_bits_on_any_threads_and_pass_size(building, {"spp": 12})
    assert "picks_probe" in base.stats


def test_a_chunked_reference_and_sample_ranges_on_dask_pick_as_one_whole_render(building, monkeypatch, tmp_path):
    # a threshold at which 12 samples probe and 11 do not: the chunks' own ranges (0-4, 5-7, 8-10, 11) would mix
    # K = 4 with the probe's choice; the reference and the Dask driver resolve K once, for the whole render (Dask's
    # worker processes do not even see the threshold changed here)
    pytest.importorskip("distributed", reason="Dask distributed is not installed (pip install -e '.[test]')")
    from lightprobe.analysis.distributed import render_on_dask
    from lightprobe.analysis.reference import render_reference

    settings = RenderSettings(spp=12, seed=5, adaptive=False)
    light_samples = 32 * 24 * MANY_LIGHTS_PICKS * 11.5
    probe = picks.probe_samples(32, 24, settings_for(building, RenderSettings(spp=1)))
    monkeypatch.setattr(picks, "PROBE_SHARE", probe / light_samples)
    whole = render(building, settings)
    assert whole.stats["lights_per_sample"] != MANY_LIGHTS_PICKS  # the probe chose
    assert "picks_probe" not in render(building, RenderSettings(spp=11, seed=5, adaptive=False)).stats
    chunked = render_reference(building, settings, tmp_path / "ref.exr", chunk=3)
    np.testing.assert_array_equal(chunked.image, whole.image)
    ranged = render_on_dask(building, settings, chunk=3, workers=1)
    np.testing.assert_allclose(ranged.image, whole.image, rtol=1e-6, atol=1e-9)
