"""The laboratory's estimator for scenes with lights (lab/light_render.py): a light selector, a user's or lightprobe's
own, renders the render core's image (z-tested), deterministically and resumably; a selector that breaks its
contract is stopped in one line, before the render or during it, keeping what was rendered."""

from pathlib import Path

import numpy as np
import pytest

from lightprobe.analysis.metrics import block_z_test
from lightprobe.bsdfs import Lambert
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.procedural import constant
from lightprobe.experiments.light_choice import selector_test_scene
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.shapes import Rectangle
from lightprobe.integrators.settings import RenderSettings
from lightprobe.integrators.wavefront import render
from lightprobe.lab import light_render
from lightprobe.lab.light_render import SelectorStrategy
from lightprobe.lab.render import LabRenderError, is_lab_token, parse_lab_token, render_lab
from lightprobe.lab.techniques import TechniqueError
from lightprobe.scene import Scene

SELECTORS = Path(__file__).parent / "user_selectors.py"


@pytest.fixture(scope="module")
def lit():
    """Every kind of light (rectangles of three sizes, a sphere, a point and a spot light, a grey sky) over a
    Lambertian floor and a Phong wall, 32 x 24, and the render core's image of it at 1,024 spp."""
    scene = selector_test_scene()
    return scene, render(scene, RenderSettings(spp=1024, seed=5, adaptive=False))


def _verdict(result, reference):
    return block_z_test(result.image, result.variance, reference.image, reference.variance, block=4)


@pytest.mark.parametrize("token", ["sel:power", "sel:bvh", "sel:uniform", f"sel:{SELECTORS}:ByPower"])
@pytest.mark.parametrize("heuristic", ["power", "balance"])
def test_a_selector_renders_the_cores_image(lit, token, heuristic):
    scene, reference = lit
    strategy, _ = parse_lab_token(token)
    result = render_lab(scene, strategy, RenderSettings(spp=64, seed=2, heuristic=heuristic))
    verdict = _verdict(result, reference)
    assert abs(verdict["pooled_z"]) < 4.0 and verdict["outliers"] <= 0.05, verdict
    assert np.isfinite(result.image).all() and result.counts.min() == 64
    assert result.stats["strategy"] == strategy.label == token.replace(f"{SELECTORS}", SELECTORS.name)
    assert result.stats["estimator"] == "lightprobe.lab (a light selector)"


def test_weights_that_do_not_sum_to_one_fail_the_same_test(lit, monkeypatch):
    """The z-test above can fail: with every MIS weight 1 the light and BSDF samples both count what they reach."""
    scene, reference = lit
    monkeypatch.setattr(light_render.LightShader, "_weight", lambda self, n_f, p_f, n_g, p_g: np.ones_like(p_f))
    result = render_lab(scene, SelectorStrategy("power"), RenderSettings(spp=64, seed=2))
    verdict = _verdict(result, reference)
    assert verdict["pooled_z"] > 4.0, verdict


def test_more_samples_of_each_technique(lit):
    scene, reference = lit
    settings = RenderSettings(spp=16, seed=3, n_bsdf=2, n_env=3)
    result = render_lab(scene, SelectorStrategy("bvh"), settings)
    verdict = _verdict(result, reference)
    assert abs(verdict["pooled_z"]) < 4.0 and verdict["outliers"] <= 0.05, verdict
    assert result.stats["directions_per_sample"] == 2 + 2 * 3  # the scene's 2 light picks x 3 light samples each


def test_the_same_image_bit_for_bit_and_resumed(lit):
    scene, _ = lit
    strategy, _ = parse_lab_token(f"sel:{SELECTORS}:ByPower")
    whole = render_lab(scene, strategy, RenderSettings(spp=4, seed=7))
    again = render_lab(scene, strategy, RenderSettings(spp=4, seed=7))
    first = render_lab(scene, strategy, RenderSettings(spp=1, seed=7))
    rest = render_lab(scene, strategy, RenderSettings(spp=3, seed=7, first_sample=1), resume=first.accumulator)
    assert np.array_equal(whole.image, again.image) and np.array_equal(whole.variance, again.variance)
    assert np.array_equal(whole.image, rest.image) and np.array_equal(whole.variance, rest.variance)
    other = render_lab(scene, strategy, RenderSettings(spp=4, seed=8))
    assert not np.array_equal(whole.image, other.image)


@pytest.mark.parametrize(
    ("name", "check"),
    [
        ("OutOfRange", "light index 7 out of range at sample"),
        ("ZeroForItsPick", "pmf 0 for the light it picked (0)"),
        ("NotNormalised", "sum to 1.1, not 1"),
        ("SelectSaysOtherwise", "but pmf() says"),
        ("PicksTheFirstTooOften", "do not follow pmf()"),
    ],
)
def test_a_selector_that_breaks_its_contract_renders_nothing(lit, name, check):
    scene, _ = lit
    strategy, _ = parse_lab_token(f"sel:{SELECTORS}:{name}")
    with pytest.raises(TechniqueError) as caught:
        render_lab(scene, strategy, RenderSettings(spp=2, seed=1))
    message = str(caught.value)
    assert f"user_selectors.py:{name}" in message and check in message and "\n" not in message, message


def test_a_selector_that_fails_mid_render_keeps_the_passes_before(lit, tmp_path):
    scene, _ = lit
    (tmp_path / "later.py").write_text(
        "import numpy as np\n"
        "class FailsOnTheThirdPass:\n"
        "    calls = 0\n"
        "    def select(self, ctx, u):\n"
        "        n = ctx.lights.count\n"
        "        return np.minimum((u * n).astype(np.int64), n - 1), np.full(len(ctx), 1.0 / n)\n"
        "    def pmf(self, ctx, light):\n"
        "        if len(ctx) > 100:\n"
        "            type(self).calls += 1\n"
        "            if type(self).calls > 2:\n"
        "                raise ValueError('tired')\n"
        "        return np.full(len(ctx), 1.0 / ctx.lights.count)\n"
    )
    strategy, _ = parse_lab_token(f"sel:{tmp_path / 'later.py'}")
    with pytest.raises(LabRenderError) as caught:
        render_lab(scene, strategy, RenderSettings(spp=8, seed=1, n_bsdf=1))
    message = str(caught.value)
    assert "later.py:FailsOnTheThirdPass.pmf raised ValueError: tired" in message and "\n" not in message, message
    assert caught.value.result is not None and caught.value.result.counts.min() == 2


def test_scenes_a_selector_cannot_render():
    scene = Scene(Camera([0, 1, 3], [0, 0, 0], resolution=(8, 6)), EnvironmentMap.from_array(constant(0.5)))
    scene.add(Rectangle.ground(size=4), Lambert(0.5))
    with pytest.raises(TechniqueError, match="has 1 light\\(s\\): a light selector's strategy needs two or more"):
        render_lab(scene, SelectorStrategy("power"), RenderSettings(spp=1))


def test_selector_tokens():
    assert is_lab_token("sel:bvh") and is_lab_token(f"sel:{SELECTORS}:ByPower/seed=3")
    strategy, overrides = parse_lab_token(f"sel:{SELECTORS}:ByPower/seed=3/heuristic=balance")
    assert strategy.label == "sel:user_selectors.py:ByPower" and overrides == ["seed=3", "heuristic=balance"]
    assert parse_lab_token("sel:power")[0].selector == "power"
    with pytest.raises(TechniqueError, match="unknown selector 'nearest'"):
        parse_lab_token("sel:nearest")
    with pytest.raises(TechniqueError, match="no selector named 'Nope'"):
        parse_lab_token(f"sel:{SELECTORS}:Nope")


def test_compare_and_render_with_selectors(tmp_path, capsys):
    """The command line: ``compare`` renders ``sel:`` strategies beside the core's; ``render --techniques`` with one;
    a selector that breaks its contract is one line and no image."""
    from lightprobe.cli import main

    from ..experiments.test_light_choice import EXAMPLES, SCENE_FILE

    path = tmp_path / "two_panels.toml"
    path.write_text(SCENE_FILE)
    report = tmp_path / "report.html"
    mine = f"sel:{EXAMPLES}:PowerOverDistance"
    code = main(["compare", str(path), "--spp", "4", "--reference-spp", "16", "-o", str(report), "-q", "--json",
                 "--light-choice-points", "0", "--strategies", f"mis,sel:bvh,{mine}/heuristic=balance"])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0 and "sel:bvh" in report.read_text() and f"{mine}/heuristic=balance" in out
    image = tmp_path / "mine.exr"
    assert main(["render", str(path), "--spp", "2", "--techniques", mine, "-o", str(image), "-q"]) == 0
    assert image.exists()
    capsys.readouterr()
    bad = tmp_path / "bad.exr"
    code = main(["render", str(path), "--spp", "2", "--techniques", f"sel:{SELECTORS}:NotNormalised", "-o", str(bad)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and not bad.exists() and err[-1].startswith("lightprobe: error: "), err
    assert "NotNormalised.pmf" in err[-1] and "check: pmfs sum to 1" in err[-1] and "Traceback" not in "".join(err)
