"""The light-choice section: the oracle, the selectors against it, and the split of a render's variance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert, Phong
from lightprobe.color import luminance
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.procedural import constant
from lightprobe.experiments import light_choice as lc
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.shapes import Rectangle
from lightprobe.integrators.settings import RenderSettings
from lightprobe.integrators.wavefront import render
from lightprobe.lab.selectors import load_selector
from lightprobe.lab.techniques import TechniqueError
from lightprobe.scene import Scene

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "light_selectors.py"
BAD = Path(__file__).resolve().parents[1] / "lab" / "user_selectors.py"


def lit_floor(blocker: bool = True, sky: bool = True) -> Scene:
    """A glossy floor under two panels and a grey sky, seen from above (no edge, no emitter in view); a board
    between the right panel and part of the floor hides some of its light (the panels hide some of the sky)."""
    env = EnvironmentMap.from_array(constant(0.3, width=16, height=8)) if sky else None
    scene = Scene(Camera([0, 1.0, 1.0], [0, 0, 0], fov=20, resolution=(8, 6)), env)
    scene.add(Rectangle.ground(size=10), Phong(0.4, 0.3, 20))
    scene.add(Rectangle([-1.5, 2, -0.5], [1, 0, 0], [0, 0, 1]), None, emission=4.0, name="left")
    scene.add(Rectangle([0.5, 2, -0.5], [1, 0, 0], [0, 0, 1]), None, emission=4.0, name="right")
    if blocker:
        scene.add(Rectangle([0.3, 0.3, -0.5], [1, 0, 0], [0, 0, 1]), Lambert(0.5), name="board")
    return scene


def per_sample_relmse(settings: RenderSettings) -> float:
    """The variance of one camera sample, as a relMSE, from a render's own samples."""
    result = render(lit_floor(), settings)
    image = luminance(result.image[..., :3].astype(np.float64))
    spread = luminance(result.variance[..., :3]) * settings.spp
    return float(np.mean(spread / (image**2 + 0.01)))


def test_the_terms_add_up_to_the_estimators_variance():
    """The split (law of total variance) against the variance of X = a V / P_l computed by enumerating every
    (light, sample) pair; choice 0 under the oracle, visibility 0 where nothing is blocked, point 0 where a light
    gives the same value everywhere."""
    rng = np.random.default_rng(5)
    n_points, n_lights, k = 7, 5, 9
    g = rng.exponential(1.0, (n_points, n_lights, k)) * (rng.random((n_points, n_lights, 1)) < 0.8)
    seen = rng.random((n_points, n_lights, k)) < 0.6
    terms = lc._LightTerms(g, np.ones_like(g), np.zeros_like(g), seen)
    pmf = rng.random((n_points, n_lights)) + 0.05
    pmf /= pmf.sum(axis=1, keepdims=True)
    mean, choice, point, visibility = lc._light_variance(lc._light_moments(terms, None), pmf)
    x = np.where(seen, g, 0.0) / pmf[:, :, None]  # the estimator's values, each with probability P_l / k
    prob = np.broadcast_to(pmf[:, :, None] / k, x.shape)
    first = (prob * x).sum(axis=(1, 2))
    second = (prob * x * x).sum(axis=(1, 2))
    np.testing.assert_allclose(mean, first, rtol=1e-12)
    np.testing.assert_allclose(choice + point + visibility, second - first**2, rtol=1e-10)
    assert np.all(choice >= 0) and np.all(point >= 0)
    m = lc._light_moments(terms, None)[0]
    oracle = m / m.sum(axis=1, keepdims=True)
    assert np.all(np.abs(lc._light_variance(lc._light_moments(terms, None), oracle)[1]) < 1e-12 * first**2)
    open_ = lc._LightTerms(g, np.ones_like(g), np.zeros_like(g), np.ones_like(seen))
    assert np.all(np.abs(lc._light_variance(lc._light_moments(open_, None), pmf)[3]) < 1e-12 * first**2)
    flat = lc._LightTerms(np.ones_like(g), np.ones_like(g), np.zeros_like(g), np.ones_like(seen))
    assert np.all(lc._light_variance(lc._light_moments(flat, None), pmf)[2] == 0.0)


@pytest.fixture(scope="module")
def measured():
    strategies = [
        (name, RenderSettings(strategy=name, sampler="independent", adaptive=False, spp=1024, seed=1,
                              outline_control_variate=False), None)
        for name in ("mis", "env", "brdf")
    ]  # fmt: skip
    users = [load_selector(f"{EXAMPLES}:Uniform"), load_selector(f"{EXAMPLES}:PowerOverDistance")]
    found = lc.measure(lit_floor(), strategies, seed=1, user_selectors=users)
    return strategies, found


def test_the_split_matches_the_renderers_own_samples(measured):
    """Each strategy's split adds up, within 8 %, to the variance of one camera sample that a 1,024-spp render of
    independent samples measures (the three techniques, the sky and the board's shadow all take part: 2-6 % apart
    at two seeds)."""
    strategies, found = measured
    assert found.points > 150 and found.lights == 3 and found.textured == 0
    for (label, settings, _), split in zip(strategies, found.splits, strict=True):
        assert split.label == label
        measured_here = per_sample_relmse(settings)
        assert split.total == pytest.approx(measured_here, rel=0.08), (label, split)
    mis, env, brdf = found.splits
    assert brdf.choice == brdf.point == brdf.visibility == 0.0 and brdf.bsdf > 0
    assert env.bsdf == 0.0 and env.visibility > 0.05 * env.total  # the board's shadow
    assert mis.choice > 0 and mis.bsdf > 0 and abs(mis.pixel) < 0.1 * mis.total  # no edge in view


def test_the_oracle_and_the_selectors(measured):
    _, found = measured
    rows = {r.name: r for r in found.selectors}
    assert list(rows)[:3] == ["uniform", "power", "bvh"]
    assert rows["oracle"].vs_oracle == 1.0 and rows["oracle"].choice == 0.0
    assert rows["variance-optimal"].total <= rows["oracle"].total
    # shadows the unoccluded oracle cannot see cost it; the BVH, which sees neither, does worse still
    assert rows["oracle"].total < rows["unoccluded oracle"].total < rows["bvh"].total
    assert 0.5 < found.arriving < 1.0
    # the user's uniform selector is lightprobe's, number for number
    mine = rows["light_selectors.py:Uniform"]
    assert (mine.choice, mine.total) == pytest.approx((rows["uniform"].choice, rows["uniform"].total), rel=1e-12)
    assert rows["light_selectors.py:PowerOverDistance"].total > 0


def test_nothing_blocked_no_visibility_term():
    found = lc.measure(lit_floor(blocker=False, sky=False), [("mis", RenderSettings(), None)], points=64, seed=2)
    assert found.arriving == pytest.approx(1.0, abs=1e-12)
    assert abs(found.splits[0].visibility) < 1e-12


def test_measured_twice_the_same():
    runs = [("env", RenderSettings(strategy="env"), None)]
    first = lc.measure(lit_floor(), runs, points=64, seed=3)
    second = lc.measure(lit_floor(), runs, points=64, seed=3, keep_tables=True)
    assert first.splits == second.splits and first.selectors == second.selectors
    # the tables behind the selectors' rows, for experiments beyond the report (benchmarks/selection_oracle.py)
    assert first.tables is None
    g, pmfs = second.tables["g"], second.tables["pmfs"]
    assert g.shape == (second.points, 3, second.per_light) == second.tables["seen"].shape
    assert set(pmfs) == {row.name for row in second.selectors}
    np.testing.assert_allclose(pmfs["oracle"].sum(axis=1), 1.0)
    assert second.tables["weight"].sum() == pytest.approx(1.0)


def test_scenes_without_a_choice_or_with_too_many_lights():
    sky_only = Scene(Camera([0, 1, 2], [0, 0, 0], resolution=(4, 3)), EnvironmentMap.from_array(constant(1.0)))
    sky_only.add(Rectangle.ground(size=10), Lambert(0.5))
    assert lc.measure(sky_only, [("mis", RenderSettings(), None)]) is None
    crowded = lit_floor()
    for i in range(40):
        crowded.add(Rectangle([i * 0.1, 3, 0], [0.05, 0, 0], [0, 0, 0.05]), None, emission=1.0, name=f"tiny{i}")
    found = lc.measure(crowded, [("mis", RenderSettings(), None)], points=512, per_light=256 * 256)
    assert found.skipped is not None and "too many for the brute-force oracle" in found.skipped
    with pytest.raises(ValueError, match="square number"):
        lc.measure(lit_floor(), [], per_light=10)


@pytest.mark.parametrize(
    ("name", "check"),
    [
        ("OutOfRange", "check: 0 <= light < 3"),
        ("ZeroForItsPick", "check: pmf > 0 where picked"),
        ("NotNormalised", "check: pmfs sum to 1"),
        ("SelectSaysOtherwise", "check: select's pmf = pmf()"),
        ("PicksTheFirstTooOften", "check: picks follow pmf()"),
        ("Raises", "check: pmf runs"),
        ("WrongShape", "check: shape and dtype"),
        ("FloatIndices", "expected integers"),
    ],
)
def test_a_selector_that_breaks_its_contract(name, check):
    """One line naming the function, the check and the first offending sample."""
    with pytest.raises(TechniqueError) as info:
        lc.check_selectors(lit_floor(), [load_selector(f"{BAD}:{name}")])
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"user_selectors.py:{name}.")
    assert check in message
    if name not in ("WrongShape", "FloatIndices"):
        assert "sample" in message


def test_a_selector_needs_lights_to_choose_from():
    sky_only = Scene(Camera([0, 1, 2], [0, 0, 0], resolution=(4, 3)), EnvironmentMap.from_array(constant(1.0)))
    sky_only.add(Rectangle.ground(size=10), Lambert(0.5))
    with pytest.raises(Exception, match="needs two or more"):
        lc.check_selectors(sky_only, [load_selector(f"{EXAMPLES}:Uniform")])


PANEL = (
    '[[objects]]\ntype = "rectangle"\norigin = [{}, 2, -0.5]\nedge_u = [1, 0, 0]\nedge_v = [0, 0, 1]\nemission = 4.0\n'
)
SCENE_FILE = (
    "[camera]\norigin = [0, 1.2, 2.5]\ntarget = [0, 0, 0]\nresolution = [16, 12]\n"
    '[materials.grey]\ntype = "lambert"\nalbedo = 0.5\n'
    '[[objects]]\ntype = "ground"\nmaterial = "grey"\n'
    + PANEL.format(-1.5)
    + PANEL.format(0.5)
    + '[[objects]]\ntype = "sphere"\ncenter = [0.6, 0.3, 0]\nradius = 0.3\nmaterial = "grey"\n'
)


def test_compare_reports_the_light_choice(tmp_path, capsys):
    from lightprobe.cli import main

    path = tmp_path / "two_panels.toml"
    path.write_text(SCENE_FILE)
    out = tmp_path / "report.html"
    args = ["compare", str(path), "--spp", "4", "--reference-spp", "16", "-o", str(out), "-q"]
    assert main([*args, "--strategies", "mis/light_sampler=bvh,mis/light_sampler=learned", "--selector",
                 f"{EXAMPLES}:PowerOverDistance", "--light-choice-points", "128"]) == 0  # fmt: skip
    text = out.read_text()
    wanted = ("Light choice", "light_selectors.py:PowerOverDistance", "unoccluded oracle", "variance-optimal",
              "learned (mis/light_sampler=learned)", "point on the light", "visibility", "measured")  # fmt: skip
    for expected in wanted:
        assert expected in text, expected
    assert text.count("<tr><td>mis/light_sampler=bvh</td><td>bvh</td>") == 1  # the split's row of the BVH's strategy
    # a selector that breaks its contract: one line, before anything is rendered (no report)
    capsys.readouterr()
    bad = tmp_path / "bad.html"
    code = main(["compare", str(path), "--spp", "2", "-o", str(bad), "-q", "--selector", f"{BAD}:NotNormalised"])
    err = capsys.readouterr().err.strip()
    assert code != 0 and not bad.exists()
    assert len(err.splitlines()) == 1 and "NotNormalised.pmf" in err and "check: pmfs sum to 1" in err
    # a selector that fails only where it is measured, after the renders: the report keeps them, says why, status 2
    late = tmp_path / "late.html"
    code = main([*args, "--strategies", "mis", "-o", str(late), "--selector", f"{BAD}:FailsOnLargeBatches"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and late.exists() and "Not measured: " in late.read_text() and "too many points" in err[-1]
    # off: no section
    assert main([*args, "--strategies", "mis", "--light-choice-points", "0", "-o", str(bad)]) == 0
    assert "Light choice" not in bad.read_text()


def test_a_large_image_classifies_a_subset_of_its_pixels():
    """Above EDGE_PIXELS pixels the edge strata are found at a random subset: the points still fill the budget and the
    pixels' weights still sum to one."""
    scene = lit_floor()
    scene.camera = scene.camera.with_resolution(320, 240)
    assert 320 * 240 > lc.EDGE_PIXELS
    found = lc.measure(scene, [("mis", RenderSettings(), None)], points=256, seed=4, keep_tables=True)
    assert found.points == 256 and found.tables["weight"].sum() == pytest.approx(1.0)
    assert all(np.isfinite(x) and x >= 0 for x in (found.splits[0].choice, found.splits[0].point))


def test_check_a_selector(capsys):
    """``lightprobe check`` knows a selector from a technique: every check on the scene of every kind of light."""
    import json

    from lightprobe.cli import main

    assert main(["check", f"{EXAMPLES}:PowerOverDistance"]) == 0
    out = capsys.readouterr().out
    assert "every check passed" in out and out.count("passed: ") == len(lc.SELECTOR_CHECKS)
    assert main(["check", f"{BAD}:PicksTheFirstTooOften", "--json"]) == 1
    verdict = json.loads(capsys.readouterr().out)
    assert verdict["passed"] is False and "check: picks follow pmf()" in verdict["failure"]
    assert main(["check", f"{BAD}:Nope"]) == 2
    assert "no selector named 'Nope'" in capsys.readouterr().err
    kinds = lc.selector_test_scene().light_table().kind
    assert len(set(kinds.tolist())) == 5  # rectangles, a sphere, a point, a spot and the sky
