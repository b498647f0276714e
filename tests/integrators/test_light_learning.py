"""Renders that learn their light selection (``light_sampler = "learned"``, integrators/light_learning.py): they learn
from their pilot and use it after; the image is the same bits for any thread count and pass size; a render that
starts past sample 0 has no pilot and uses the BVH; learning leaves the mean where it was."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.reference_scenes import build

from .test_wavefront import assert_the_same_bits_on_any_threads_and_pass_size


@pytest.fixture(scope="module")
def scene():
    # the suite's building (most light behind walls: what learning is for), small
    return build("building", resolution=(32, 24))


@pytest.mark.parametrize("adaptive", [None, False])
def test_a_learning_render_is_the_same_bits_on_any_threads_and_pass_size(scene, adaptive):
    options = {"spp": 32, "light_sampler": "learned", "adaptive": adaptive}  # adaptive: learns from 4 of 8
    base = assert_the_same_bits_on_any_threads_and_pass_size(scene, options)
    assert base.stats["learned_cells"] > 0 and base.stats["learned_levels"] >= 1
    bvh = render(scene, RenderSettings(threads=2, **{**options, "light_sampler": "bvh"}))
    assert bvh.image.tobytes() != base.image.tobytes()  # what it learned changed the samples after the pilot
    assert "learned_cells" not in bvh.stats


def test_a_render_continued_from_its_statistics_learns_what_the_whole_render_learned(scene):
    # a uniform render learns after its first 4 samples whatever its spp, and its statistics carry what it learned
    # (through the arrays a reference's checkpoint files hold): stopped at 7 and continued, the same bits as 16
    from lightprobe.errors import ParameterError
    from lightprobe.integrators.accumulation import Accumulator

    options = {"light_sampler": "learned", "adaptive": False}
    whole = render(scene, RenderSettings(spp=16, **options))
    first = render(scene, RenderSettings(spp=7, **options))
    assert first.accumulator.learned is not None and first.stats["learned_cells"] == whole.stats["learned_cells"] > 0
    carried = Accumulator.from_arrays(first.accumulator.to_arrays())
    resumed = render(scene, RenderSettings(spp=9, first_sample=7, pass_samples=50, **options), resume=carried)
    np.testing.assert_array_equal(resumed.image, whole.image)
    np.testing.assert_array_equal(resumed.variance, whole.variance)
    other = build("many", resolution=scene.camera.resolution, lights=200)
    with pytest.raises(ParameterError, match="learned light selection made for another scene"):
        render(other, RenderSettings(spp=9, first_sample=7, **options), resume=carried)


def test_a_reference_in_short_chunks_and_sample_ranges_on_dask_pick_as_one_whole_render(scene, tmp_path):
    """A reference's first chunk holds the pilot the selection learns from (4 samples) and one more, whatever
    --chunk says; on Dask the range from sample 0 is rendered first and the other ranges pick with what it learned:
    both give the image of one whole render (before, chunks of 2 never learned, and Dask's later ranges never did)."""
    pytest.importorskip("distributed", reason="Dask distributed is not installed (pip install -e '.[test]')")
    from lightprobe.analysis.distributed import render_on_dask
    from lightprobe.analysis.reference import render_reference

    settings = RenderSettings(spp=12, seed=5, adaptive=False)  # the default selection: learned
    whole = render(scene, settings)
    assert whole.stats["learned_cells"] > 0
    chunked = render_reference(scene, settings, tmp_path / "ref.exr", chunk=2)
    np.testing.assert_array_equal(chunked.image, whole.image)
    ranged = render_on_dask(scene, settings, chunk=3, workers=1)  # its process loads the kernels compiled here
    assert ranged.stats["ranges"] == 4  # samples 0-4 (the pilot and one more), 5-7, 8-10, 11
    assert ranged.accumulator.learned is not None
    np.testing.assert_allclose(ranged.image, whole.image, rtol=1e-6, atol=1e-9)


def test_a_render_past_sample_0_has_no_pilot_and_picks_with_the_bvh(scene):
    learned = render(scene, RenderSettings(spp=6, first_sample=4, light_sampler="learned"))
    bvh = render(scene, RenderSettings(spp=6, first_sample=4, light_sampler="bvh"))
    assert "learned_cells" not in learned.stats
    np.testing.assert_array_equal(learned.image, bvh.image)


@pytest.mark.parametrize("picks", [None, 16])
def test_a_learning_render_agrees_with_mitsuba_on_the_building(picks):
    # Mitsuba 3's direct integrator, emitters sampled by power, 65,536 spp (benchmarks/mitsuba_references.py
    # --scenes building): per-pixel and pooled z-tests as every reference case, with our own variance (Mitsuba's
    # per-sample variance here is many times ours: as a floor it would leave the pooled test blind to a 10 % bias);
    # and with the 16 picks a probe chooses for the building in a larger image (decisions.md 123)
    from .test_references import assert_agrees_with_mitsuba

    spp = 1024 if picks is None else 256
    options = {"light_sampler": "learned", "spp": spp, "adaptive": False, "lights_per_sample": picks}
    ours = assert_agrees_with_mitsuba("building", build("building", resolution=(64, 48)), options, False)
    assert ours.stats["learned_cells"] > 0


def test_learning_leaves_the_mean_where_it_was(scene):
    # the building at 256 spp, four seeds each: the images' pooled difference within noise, the noise under 1 %
    # of the image
    sums, variances = {}, {}
    for sampler in ("bvh", "learned"):
        images = [
            render(scene, RenderSettings(spp=256, seed=seed, light_sampler=sampler, adaptive=False))
            for seed in range(4)
        ]
        assert ("learned_cells" in images[0].stats) == (sampler == "learned")
        sums[sampler] = sum(r.image.astype(np.float64) for r in images) / 4
        variances[sampler] = sum(r.variance.astype(np.float64) for r in images) / 16
    for c in range(3):
        difference = sums["learned"][..., c].sum() - sums["bvh"][..., c].sum()
        sigma = np.sqrt(variances["learned"][..., c].sum() + variances["bvh"][..., c].sum())
        assert abs(difference) < 4 * sigma, (c, difference / sigma)
        assert sigma < 0.01 * sums["bvh"][..., c].sum()


def test_compiling_the_learning_kernels_records_nothing_and_runs_every_kernel(scene, monkeypatch):
    # a first render compiles the learning's kernels in its warm-up (decisions.md 135): with the pass's own record
    # types, while recording nothing and learning nothing; the made-up records must take ``learned`` to its last
    # kernel, or the pilot would still compile that one
    from lightprobe.emitters import selection_learning
    from lightprobe.geometry.raytracer import RayTracer
    from lightprobe.integrators.accumulation import Accumulator
    from lightprobe.integrators.schedule import pass_pixels
    from lightprobe.integrators.wavefront import _Pass, resolve

    arrays = scene.compile()
    n_pixels = int(np.prod(scene.camera.resolution))
    plan = resolve(scene, RenderSettings(spp=16, light_sampler="learned", adaptive=False))
    work = _Pass(scene, plan, arrays, RayTracer(arrays), n_pixels, 1)
    work.make_buffers()
    assert work.learning is not None
    selector = work.learning.selector
    reached = []
    last_kernel = selection_learning._learned_probabilities
    monkeypatch.setattr(
        selection_learning, "_learned_probabilities", lambda *args: reached.append(1) or last_kernel(*args)
    )
    work.learning.compile_kernels(work.records(Accumulator(n_pixels), pass_pixels(0, 1), 1, 0))
    assert reached == [1]
    assert work.learning.recording and work.learning.selector is selector
    assert np.all(work.learning.records.light == -1)  # nothing recorded
