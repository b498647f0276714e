"""The laboratory's estimator: built-in and user techniques rendered like the render core, deterministic, resumable,
and a failing user technique keeps what was rendered."""

from pathlib import Path

import numpy as np
import pytest

from lightprobe.analysis.metrics import block_z_test
from lightprobe.bsdfs import Lambert
from lightprobe.errors import LightprobeError
from lightprobe.experiments.compare import compare
from lightprobe.integrators.settings import RenderSettings
from lightprobe.integrators.wavefront import render
from lightprobe.lab.render import LabRenderError, LabStrategy, parse_lab_token, render_lab
from lightprobe.lab.techniques import TechniqueError, builtin

HERE = Path(__file__).parent
SOLUTIONS = HERE / "solutions" / "sampling.py"
TECHNIQUES = HERE / "user_techniques.py"


def _z(result, reference, block=6):
    return block_z_test(result.image, result.variance, reference.image, reference.variance, block=block)


@pytest.mark.parametrize("sampler", ["sobol", "independent"])
@pytest.mark.parametrize("strategy", ["mis", "brdf", "env"])
def test_lightprobes_techniques_through_the_lab_give_the_cores_image_bit_for_bit(exercise_scene, sampler, strategy):
    """The laboratory's estimator takes the core's random numbers in the core's layout (a technique's samples one
    stratified group): with lightprobe's own techniques it must reproduce the render core's image exactly."""
    scene, _ = exercise_scene
    techniques = {"mis": ("bsdf", "light"), "brdf": ("bsdf",), "env": ("light",)}[strategy]
    settings = RenderSettings(spp=4, seed=3, heuristic="balance", sampler=sampler, strategy=strategy)
    core = render(scene, settings)
    lab = render_lab(scene, LabStrategy(tuple(builtin(k) for k in techniques), "balance"), settings)
    assert np.array_equal(core.image, lab.image) and np.array_equal(core.variance, lab.variance)


@pytest.mark.parametrize(
    "token",
    [
        "builtin",
        f"mis:{SOLUTIONS}:PhongLobes",
        f"mis:{SOLUTIONS}:EnvironmentMapSampler",
        f"mis:{SOLUTIONS}:PhongLobes+{SOLUTIONS}:EnvironmentMapSampler",
    ],
)
@pytest.mark.parametrize("seed", [1, 2])
def test_user_techniques_under_mis_match_the_render_core(exercise_scene, token, seed):
    scene, reference = exercise_scene
    if token == "builtin":
        strategy = LabStrategy((builtin("bsdf"), builtin("light")), "balance")
    else:
        strategy, _ = parse_lab_token(token)
        strategy.heuristic = "balance"
    result = render_lab(scene, strategy, RenderSettings(spp=32, seed=seed))
    verdict = _z(result, reference)
    assert abs(verdict["pooled_z"]) < 4.0 and verdict["outliers"] <= 0.05, verdict
    assert np.isfinite(result.image).all() and result.counts.min() == 32


def test_a_technique_alone_matches_too(exercise_scene):
    scene, reference = exercise_scene
    strategy, _ = parse_lab_token(f"{SOLUTIONS}:EnvironmentMapSampler")
    result = render_lab(scene, strategy, RenderSettings(spp=32, seed=3))
    assert result.stats["directions_per_sample"] == 16  # the 8 + 8 of an environment-lit scene, all its own
    verdict = _z(result, reference)
    assert abs(verdict["pooled_z"]) < 4.0, verdict


def test_the_test_sees_a_biased_heuristic(exercise_scene):
    """Weights that sum to 1.1 (each +0.05) brighten the image by a few per cent: the z-test must fail."""
    scene, reference = exercise_scene

    def over(n_f, p_f, n_g, p_g):
        return np.minimum(n_f * p_f / np.maximum(n_f * p_f + n_g * p_g, 1e-300) + 0.05, 1.0)

    result = render_lab(scene, LabStrategy((builtin("bsdf"), builtin("light")), over), RenderSettings(spp=32, seed=1))
    assert _z(result, reference)["pooled_z"] > 4.0


@pytest.mark.parametrize("ending", ["raise", "exit"])
def test_a_heuristic_that_raises_or_exits_is_a_technique_error(exercise_scene, ending):
    """A user's NumPy heuristic is the user's code like a technique: a raise was a traceback and a sys.exit() ended
    the program; both are one error naming it, with what was rendered before it."""
    import sys

    scene, _ = exercise_scene

    def broken(n_f, p_f, n_g, p_g):
        if ending == "exit":
            sys.exit(3)
        raise ZeroDivisionError("my weights")

    with pytest.raises(LabRenderError, match=r"broken raised (SystemExit: 3|ZeroDivisionError: my weights)"):
        render_lab(scene, LabStrategy((builtin("bsdf"), builtin("light")), broken), RenderSettings(spp=2, seed=1))


def test_deterministic_and_resumable(exercise_scene):
    scene, _ = exercise_scene
    strategy, _ = parse_lab_token(f"mis:{SOLUTIONS}:PhongLobes")
    whole = render_lab(scene, strategy, RenderSettings(spp=4, seed=5))
    again = render_lab(scene, strategy, RenderSettings(spp=4, seed=5))
    first = render_lab(scene, strategy, RenderSettings(spp=1, seed=5))
    rest = render_lab(scene, strategy, RenderSettings(spp=3, seed=5, first_sample=1), resume=first.accumulator)
    assert np.array_equal(whole.image, again.image)
    assert np.array_equal(whole.image, rest.image) and np.array_equal(whole.variance, rest.variance)
    other = render_lab(scene, strategy, RenderSettings(spp=4, seed=6))
    assert not np.array_equal(whole.image, other.image)


def test_a_failing_technique_keeps_what_was_rendered(exercise_scene):
    scene, _ = exercise_scene
    strategy, _ = parse_lab_token(f"{TECHNIQUES}:FailsLater")
    with pytest.raises(LabRenderError, match="ran out of luck") as info:
        render_lab(scene, strategy, RenderSettings(spp=8, seed=1))
    kept = info.value.result
    assert kept is not None and kept.counts.min() == 1 and np.isfinite(kept.image).all()
    assert "1 sample(s) per pixel kept" in str(info.value)


def test_a_technique_failing_in_a_continued_render_counts_what_the_render_holds(exercise_scene):
    """A render that continues another (compare's rounds do) and fails in its first pass holds the samples it
    continued: the error counts them and carries them. Before, it said "0 sample(s) per pixel kept" (and carried
    nothing), which compare put beside "stopped at 1 spp"."""
    scene, _ = exercise_scene
    strategy, _ = parse_lab_token(f"{TECHNIQUES}:FailsLater")
    first = render_lab(scene, strategy, RenderSettings(spp=1, seed=1))
    with pytest.raises(LabRenderError) as info:
        render_lab(scene, strategy, RenderSettings(spp=2, seed=1, first_sample=1), resume=first.accumulator)
    assert "(during sample 1; 1 sample(s) per pixel kept)" in str(info.value), str(info.value)
    kept = info.value.result
    assert kept is not None and kept.counts.min() == kept.counts.max() == 1
    assert np.array_equal(kept.image, first.image)


def test_strategy_tokens_and_scene_checks(exercise_scene):
    with pytest.raises(TechniqueError, match="MIS needs one BSDF and one light"):
        parse_lab_token(f"mis:{SOLUTIONS}:PhongLobes+{SOLUTIONS}:CosineHemisphere")
    with pytest.raises(TechniqueError, match="two techniques need the mis: prefix"):
        parse_lab_token(f"{SOLUTIONS}:PhongLobes+{SOLUTIONS}:EnvironmentMapSampler")
    strategy, overrides = parse_lab_token(f"mis:{SOLUTIONS}:PhongLobes/seed=3/heuristic=power")
    assert overrides == ["seed=3", "heuristic=power"] and strategy.label.startswith("mis:sampling.py:PhongLobes+")
    from lightprobe.reference_scenes import build

    area = build("area")
    with pytest.raises(TechniqueError, match="environment map alone"):
        render_lab(area, strategy, RenderSettings(spp=1))
    from lightprobe.geometry.mesh import TriangleMesh
    from lightprobe.scene import Scene
    from lightprobe.textures import ImageTexture, MaterialTextures

    scene, _ = exercise_scene
    textured = Scene(scene.camera, scene.environment)
    quad = TriangleMesh.from_arrays([[0, 0, 0], [1, 0, 0], [1, 0, 1]], [[0, 2, 1]], uvs=[[0, 0], [1, 0], [1, 1]])
    textured.add(quad, Lambert(0.5, textures=MaterialTextures(base_color=ImageTexture([[0.5]]))), name="tile")
    with pytest.raises(TechniqueError, match="user techniques render untextured materials; 'tile material' has"):
        render_lab(textured, strategy, RenderSettings(spp=1))


def test_compare_takes_user_strategies(exercise_scene):
    scene, reference = exercise_scene
    runs = compare(
        scene,
        ["mis", f"mis:{SOLUTIONS}:PhongLobes", f"{TECHNIQUES}:FailsLater", "lab:mis"],
        reference.image,
        reference.variance,
        spp=4,
    )
    # lightprobe's techniques through the laboratory: the core's image, so the same error (at the lab's speed)
    assert runs[3].metrics["mse"] == runs[0].metrics["mse"] and np.array_equal(runs[3].image, runs[0].image)
    assert runs[0].label == "mis" and runs[0].error is None
    assert runs[1].spp == 4 and runs[1].error is None and runs[1].metrics["relmse"] > 0
    assert runs[2].error is not None and "ran out of luck" in runs[2].error and runs[2].rounds


def test_the_render_clock_does_not_count_compiling():
    """A render's time limit is the render's, not Numba's: a compile (or a load from the cache) on a kernel's first
    use, in the first pass, is not counted, as the render core warms up its stages before its clock starts."""
    import time

    import numba

    from lightprobe.lab.techniques import RenderClock

    @numba.njit
    def fresh(x):  # compiled at its first call, under Numba's compiler lock
        return x + 1.0

    with RenderClock(1000.0) as clock:
        fresh(1.0)
        wall = time.perf_counter() - clock.start
        spent = clock.seconds_spent()
    assert 0.0 <= spent < wall - 0.01, (spent, wall)
    assert RenderClock(None).seconds_left() is None


def test_a_technique_too_slow_for_a_pass_at_equal_time_is_one_error(exercise_scene):
    """At equal time a user technique slower than the whole budget (5 s a call, 0.5 s given) is stopped by the time
    limit; with nothing rendered there is nothing to measure, and the error says so (before, it ran its first pass
    to the end, 10-15 s, and was measured)."""
    scene, reference = exercise_scene
    with pytest.raises(LightprobeError, match=r"Slow': the 0.5 s ran out before its first pass was finished"):
        compare(scene, [f"{TECHNIQUES}:Slow"], reference.image, reference.variance, equal="time", seconds=0.5)
