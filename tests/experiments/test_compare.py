"""lightprobe compare: strategies parsed, rendered at equal samples or equal time, measured."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.errors import LightprobeError
from lightprobe.experiments.compare import compare, parse_strategy
from lightprobe.integrators.settings import AUTO_BSDF_SAMPLES
from lightprobe.integrators.wavefront import RenderSettings, render

from ..integrators.test_wavefront import small_scene


@pytest.fixture(scope="module")
def scene_and_reference():
    scene = small_scene((32, 24))
    ref = render(scene, RenderSettings(spp=1024, seed=99))
    return scene, ref


def test_strategy_tokens():
    base = RenderSettings(seed=3)
    label, s = parse_strategy("mis-balance", base)
    assert (label, s.strategy, s.heuristic, s.seed) == ("mis-balance", "mis", "balance", 3)
    _, s = parse_strategy("mis-power/sampler=independent/bsdf_samples=2", base)
    assert (s.heuristic, s.sampler, s.n_bsdf) == ("power", "independent", 2)
    _, s = parse_strategy("env/env_candidates=4", base)
    assert (s.strategy, s.env_candidates) == ("env", 4)
    for token, message in [
        ("best", "unknown strategy 'best'"),
        ("mis/colour=red", "is not key=value with a key among"),
        ("mis/bsdf_samples=0/env_samples=0", "sample counts"),
        ("mis/spp=4", "is not key=value"),
    ]:
        with pytest.raises(LightprobeError, match=message):
            parse_strategy(token, base)
    for equal in ("spp", "time"):  # an adaptive strategy at equal samples or at equal time
        _, s = parse_strategy("mis/adaptive=true", base, equal)
        assert s.adaptive is True
    with pytest.raises(LightprobeError, match="adaptive sampling needs spp >= 4"):
        parse_strategy("mis/adaptive=true", base, "spp", 2)


def test_equal_samples(scene_and_reference):
    scene, ref = scene_and_reference
    runs = compare(scene, ["brdf", "env", "mis-power", "mis"], ref.image, ref.variance, equal="spp", spp=16)
    for r in runs:
        assert r.spp == 16 and [row["spp"] for row in r.rounds] == [1, 2, 4, 8, 16]
        assert r.image.shape == (24, 32, 3) and np.isfinite(r.image).all()
        assert r.rounds[-1]["mse"] == pytest.approx(r.metrics["mse"])
        assert set(r.metrics) >= {"mse", "relmse", "psnr", "flip", "bias", "efficiency", "relative_efficiency"}
    by = {r.label: r for r in runs}
    # each run states the settings render used: the automatic allocation and heuristic made concrete
    assert (by["mis-power"].settings.n_bsdf, by["mis-power"].settings.heuristic) == (AUTO_BSDF_SAMPLES, "power")
    assert by["brdf"].settings.n_bsdf == AUTO_BSDF_SAMPLES and by["env"].settings.heuristic == "balance"
    assert max(r.metrics["relative_efficiency"] for r in runs) == 1.0
    # MIS with the renderer's defaults beats either technique alone at equal rays (here 0.00088 against brdf's
    # 0.0081 and env's 0.0011: this scene's 12-degree sun suits 5 stratified environment samples, which tie
    # with the power heuristic's MIS)
    assert by["mis"].settings.heuristic == "balance"
    assert by["mis"].metrics["mse"] < min(by["brdf"].metrics["mse"], by["env"].metrics["mse"])
    # the convergence is real: 16 spp has less error than 1 spp
    assert by["mis-power"].rounds[-1]["mse"] < by["mis-power"].rounds[0]["mse"]


def test_equal_time_spends_equal_time(scene_and_reference):
    scene, ref = scene_and_reference
    budget = 1.0
    runs = compare(scene, ["env", "mis-power", "mis-power/env_candidates=8"], ref.image, equal="time", seconds=budget)
    for r in runs:
        # a render's last round takes the samples that fit in the time left, to the nearest one: it may end a
        # fraction of a (millisecond) round before the budget as well as after it; after it by more where the other
        # test process slows this one's last round below the pace it measured (1.10 s seen on the loaded CI)
        assert 0.95 * budget <= r.seconds <= 1.25 * budget, (r.label, r.seconds)
    spp = {r.label: r.spp for r in runs}
    assert spp["mis-power/env_candidates=8"] < spp["mis-power"]  # a costlier strategy gets fewer samples


def test_bad_comparisons(scene_and_reference):
    scene, ref = scene_and_reference
    with pytest.raises(LightprobeError, match="equal must be"):
        compare(scene, ["env"], ref.image, equal="quality")
    with pytest.raises(LightprobeError, match="the reference is 8x8"):
        compare(scene, ["env"], np.zeros((8, 8, 3)))
    with pytest.raises(LightprobeError, match="at least one strategy"):
        compare(scene, [], ref.image)


def test_per_object_metrics(scene_and_reference):
    from lightprobe.analysis import metrics
    from lightprobe.analysis.masks import object_id_pass

    scene, ref = scene_and_reference
    ids, names = object_id_pass(scene)
    masks = {name: ids == i for i, name in enumerate(names)}
    (run,) = compare(scene, ["mis-power"], ref.image, ref.variance, spp=4, masks=masks)
    seen = {name for name, mask in masks.items() if mask.any()}
    assert set(run.metrics["objects"]) == seen and len(seen) >= 2
    for name in seen:
        assert run.metrics["objects"][name]["mse"] == pytest.approx(metrics.mse(run.image, ref.image, masks[name]))


def test_an_adaptive_strategy_renders_each_round_afresh(scene_and_reference):
    """Adaptive counts need a whole pilot, so its rounds (4, 8, 16 spp on average) are separate renders: each has
    at most its mean count, its own seconds, and the last is the run's image -- unbiased against the reference."""
    scene, ref = scene_and_reference
    uniform, adaptive = compare(scene, ["mis", "mis/adaptive=true"], ref.image, ref.variance, equal="spp", spp=16)
    assert [round(row["spp"]) for row in uniform.rounds] == [1, 2, 4, 8, 16]
    assert uniform.settings.adaptive is False  # the renderer's automatic adaptive counts: not in continued rounds
    assert len(adaptive.rounds) == 3
    for row, n in zip(adaptive.rounds, (4, 8, 16), strict=True):
        assert n / 2 < row["spp"] <= n
    assert adaptive.seconds == adaptive.rounds[-1]["seconds"] and adaptive.spp == adaptive.rounds[-1]["spp"]
    assert adaptive.rounds[-1]["mse"] == pytest.approx(adaptive.metrics["mse"])
    assert adaptive.settings.adaptive and np.isfinite(adaptive.image).all()
    assert adaptive.metrics["bias_low"] <= 0.0 <= adaptive.metrics["bias_high"]
    with pytest.raises(LightprobeError, match="adaptive sampling needs spp >= 4"):
        compare(scene, ["mis/adaptive=true"], ref.image, equal="spp", spp=2)


def test_an_adaptive_strategy_at_equal_time_plans_each_round_to_its_budget(scene_and_reference):
    """At equal time an adaptive strategy's rounds are renders limited to an eighth, a quarter, half and all of
    the budget, each planning its pilot and mean count from the time its pilot took."""
    scene, ref = scene_and_reference
    budget = 1.0
    (run,) = compare(scene, ["mis/adaptive=true"], ref.image, ref.variance, equal="time", seconds=budget)
    assert len(run.rounds) == 4 and run.settings.adaptive
    assert run.seconds == run.rounds[-1]["seconds"] <= 1.1 * budget, run.rounds
    assert run.rounds[-1]["spp"] > 2 * run.rounds[0]["spp"]  # eight times the seconds buy more samples
    assert np.isfinite(run.image).all() and run.metrics["bias_low"] <= 0.0 <= run.metrics["bias_high"]


def test_a_learned_selection_learns_in_compares_rounds():
    """A ``light_sampler=learned`` strategy's first round holds more than the 4 samples it learns from (its rounds
    began at 1 spp, learned nothing and picked as the BVH); its later rounds continue with what it learned."""
    from lightprobe.integrators.light_learning import cells_learned
    from lightprobe.reference_scenes import build

    scene = build("many")  # 64 x 48: the test references' scene, whose stages other tests compile too
    reference = np.full((48, 64, 3), 0.1)  # the metrics are not what is tested
    learned, bvh = compare(scene, ["mis", "mis/light_sampler=bvh"], reference, spp=16, base=RenderSettings(seed=2))
    assert learned.settings.light_sampler == "learned"  # the default
    assert learned.learned is not None and cells_learned(learned.learned) > 0
    assert [r["spp"] for r in learned.rounds] == [8.0, 16.0] and bvh.rounds[0]["spp"] == 1.0
    assert not np.array_equal(learned.image, bvh.image)


def test_a_scene_with_nothing_to_learn_keeps_rounds_of_one_two_four_samples(scene_and_reference):
    """The default (learned) selector on a scene lit by an environment map alone: nothing to learn, so its rounds
    start at one sample, as every strategy's did before the default changed (decision 117)."""
    scene, ref = scene_and_reference
    (run,) = compare(scene, ["mis"], ref.image, equal="spp", spp=4)
    assert run.settings.light_sampler == "learned" and run.learned is None
    assert [r["spp"] for r in run.rounds] == [1.0, 2.0, 4.0]
