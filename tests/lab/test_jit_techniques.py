"""User techniques written as numba.njit functions: checked like NumPy ones, rendered by the laboratory's compiled
estimator like the render core (z-test), deterministic on any thread count, resumable, and every way a call can go
wrong one clear error."""

import functools
from pathlib import Path

import numba
import numpy as np
import pytest

from lightprobe.analysis.metrics import block_z_test
from lightprobe.integrators.settings import RenderSettings
from lightprobe.lab.check import check_technique
from lightprobe.lab.jit_techniques import material_record
from lightprobe.lab.render import LabRenderError, LabStrategy, parse_lab_token, render_lab
from lightprobe.lab.techniques import GuardedTechnique, TechniqueError, builtin, load_module, load_technique

HERE = Path(__file__).parent
EXAMPLE = HERE.parents[1] / "examples" / "njit_sampling.py"
TECHNIQUES = HERE / "user_techniques_jit.py"
SOLUTIONS = HERE / "solutions" / "sampling.py"
N = 100_000


def check(name, path=TECHNIQUES, **kwargs):
    return check_technique(load_technique(f"{path}:{name}", time_limit=kwargs.pop("time_limit", 60.0)), samples=N,
                           **kwargs)  # fmt: skip


@functools.cache
def _module(path):
    """A technique file imported once per test module: its njit functions are then the same objects in every render
    here, so the loops compiled for them (5-12 s each) compile once, not per test."""
    return load_module(path)


def _njit_mis(heuristic="balance"):
    example = _module(EXAMPLE)
    techniques = (
        GuardedTechnique(example.PhongLobes(), "PhongLobes"),
        GuardedTechnique(example.EnvironmentMap(), "EnvironmentMap"),
    )
    return LabStrategy(techniques, example.balance_heuristic if heuristic == "njit" else heuristic)


# --- check -----------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["CosineHemisphere", "PhongLobes", "EnvironmentMap"])
def test_the_njit_examples_pass_every_check(name):
    technique = load_technique(f"{EXAMPLE}:{name}")
    assert technique.jit is not None  # called one sample at a time, compiled
    report = check(name, EXAMPLE)
    assert report.passed, report.text()
    assert {"runs", "sample pdf = pdf()", "integrates to 1", "chi-square"} <= {i.name for i in report.items}


@pytest.mark.parametrize(
    ("name", "check_name", "words"),
    [
        ("MapWithoutSinTheta", "integrates to 1", "missing the sin theta of the lat-long Jacobian"),
        ("CosineUnnormalised", "integrates to 1", "1/pi"),
        ("CosineBelow", "below the surface", "below the surface"),
    ],
)
def test_njit_mistakes_fail_with_their_cause(name, check_name, words):
    failure = check(name).first_failure
    assert failure is not None and failure.name == check_name, failure
    assert words in failure.message


@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("Raises", ["Raises.sample raised ValueError: my njit bug", "user_techniques_jit.py", "u = ["]),
        ("ReturnsNaN", ["pdf is not finite at sample", "check: finite values"]),
        ("NegativePdf", ["negative pdf -1 at sample 0", "check: pdf >= 0"]),
        ("NotUnit", ["wi is not a unit vector at sample 0", "|wi| = 2"]),
        ("DoesNotCompile", ["DoesNotCompile.sample: numba could not compile it", "check: compiles"]),
    ],
)
def test_bad_njit_output_is_one_clear_failure(name, words):
    failure = check(name).first_failure
    assert failure is not None and failure.name == "runs"
    assert "\n" not in failure.message
    for w in words:
        assert w in failure.message, failure.message


def test_the_raising_sample_is_the_first_one_that_raises():
    technique = load_technique(f"{TECHNIQUES}:Raises")
    u = np.full((1000, 2), 0.25)
    u[617, 0] = 0.75
    from lightprobe.lab.techniques import Context

    with pytest.raises(TechniqueError, match=r"sample 617 of a batch of 1000, u = \[0\.75, 0\.25\]"):
        technique.sample(u, Context.local([0.0, 0.0, 1.0], 1000))


def test_a_slow_njit_technique_is_stopped():
    assert "took longer than 0.2 s" in check("Slow", time_limit=0.2).first_failure.message


def test_compiling_is_not_counted_against_the_time_limit():
    """Numba compiles a fresh technique's loops in seconds, before its first call's limit starts: a fast technique
    passes under a limit shorter than its compile (and the limit's signal never lands inside the compiler)."""
    report = check("Cosine", time_limit=0.5)
    assert report.passed, report.text()


def test_njit_functions_that_cannot_be_called_are_refused_at_load():
    with pytest.raises(TechniqueError, match=r"TakesSelf.sample: an njit function cannot take self: make it a "
                       r"@staticmethod"):  # fmt: skip
        load_technique(f"{TECHNIQUES}:TakesSelf")
    with pytest.raises(TechniqueError, match=r"sample is a numba\.njit function but pdf is not"):
        load_technique(f"{TECHNIQUES}:OnlySampleIsNjit")
    technique = load_technique(f"{TECHNIQUES}:Cosine")
    technique.user.data = np.zeros(3)
    with pytest.raises(TechniqueError, match="data must be a tuple"):
        technique.data()


def test_material_records_share_a_type_per_class():
    """Numba compiles a loop per record type: every Phong must give the same one (not a type per material)."""
    from lightprobe.bsdfs import Lambert, Phong

    a, b = material_record(Phong(0.2, 0.3, 10.0)), material_record(Phong(0.5, 0.1, 40.0))
    assert type(a) is type(b) and a.exponent == 10.0 and b.exponent == 40.0
    assert np.array_equal(b.rho_d, [0.5, 0.5, 0.5]) and a.kind == b.kind
    assert type(material_record(Lambert(0.5))) is not type(a)


def test_a_users_technique_alone_sees_the_map_without_lightprobes_kernel_record(exercise_scene):
    """Numba compiles a context's every field: a user's loops get the map's record without lightprobe's ~25 kernel
    arrays (decisions.md 136), the same record each call; lightprobe's map sampling gets the kernel."""
    from lightprobe.integrators.batch_estimator import Context
    from lightprobe.lab.jit_techniques import environment_record

    env = exercise_scene[0].environment
    full, slim = environment_record(env), environment_record(env, kernel=False)
    assert full.kernel is env.kernel and len(full.kernel) > 10 and slim.kernel == ()
    assert slim.luminance is full.luminance and environment_record(env, kernel=False) is slim
    technique = load_technique(f"{TECHNIQUES}:Cosine").technique
    ctx = Context.local([0.3, 0.2, 0.9], 4, environment=env)
    assert technique.arguments(ctx)[5] is slim
    wi, pdf = technique.sample(np.full((4, 2), 0.25), ctx)
    assert np.allclose(np.linalg.norm(wi, axis=1), 1.0) and np.allclose(pdf, wi[:, 2] / np.pi)


# --- render ----------------------------------------------------------------------------------------------------------
def test_lightprobes_twins_beside_a_users_technique_take_records_that_can_be_cached(exercise_scene):
    """Under ``mis:`` a user's BSDF sampling runs beside lightprobe's map sampling. The map sampling's njit twins
    get the material as its kernel block (a type of the module, which Numba's disk cache finds again), not the
    user's named tuple made at run time (compiled anew every run, 1.9 s); the user's functions get the map without
    lightprobe's kernel arrays (decisions.md 136)."""
    from lightprobe.lab import jit_techniques as jt

    strategy, _ = parse_lab_token(f"mis:{EXAMPLE}:PhongLobes")
    result = render_lab(exercise_scene[0], strategy, RenderSettings(spp=1, seed=3))
    assert result.stats["estimator"] == "lightprobe.lab (user techniques, compiled)"
    for twin in (jt.builtin_env_sample, jt.builtin_env_pdf):
        materials = {signature[1].types[4] for signature in twin.signatures}  # ctx.material's Numba type
        assert materials and all(m.instance_class is jt.KernelMaterial for m in materials), materials
    user = next(t for t in strategy.techniques if not t.builtin)
    for function in user.jit:
        assert {signature[1].types[5].types[3] for signature in function.signatures} == {numba.types.Tuple(())}


@pytest.mark.parametrize("seed", [1, 2])
def test_njit_techniques_under_mis_match_the_render_core(exercise_scene, seed):
    scene, reference = exercise_scene
    result = render_lab(scene, _njit_mis("njit"), RenderSettings(spp=32, seed=seed))
    assert result.stats["estimator"] == "lightprobe.lab (user techniques, compiled)"
    verdict = block_z_test(result.image, result.variance, reference.image, reference.variance, block=6)
    assert abs(verdict["pooled_z"]) < 4.0 and verdict["outliers"] <= 0.05, verdict
    assert np.isfinite(result.image).all() and result.counts.min() == 32


def test_the_z_test_sees_an_njit_heuristic_that_over_weights(exercise_scene):
    scene, reference = exercise_scene
    jit = _module(TECHNIQUES)
    strategy = LabStrategy((builtin("bsdf"), builtin("light")), jit.over_weighted)
    result = render_lab(scene, strategy, RenderSettings(spp=32, seed=1))
    assert result.stats["estimator"].endswith("compiled)")
    verdict = block_z_test(result.image, result.variance, reference.image, reference.variance, block=6)
    assert verdict["pooled_z"] > 4.0


def test_the_compiled_and_numpy_estimators_agree(exercise_scene):
    """The same njit techniques with a NumPy heuristic go through the NumPy estimator (each technique a batch
    through its compiled loop): the same image to rounding."""
    scene, _ = exercise_scene
    solutions = _module(SOLUTIONS)
    compiled = render_lab(scene, _njit_mis("njit"), RenderSettings(spp=4, seed=7))
    numpy_path = render_lab(scene, _njit_mis(solutions.balance_heuristic), RenderSettings(spp=4, seed=7))
    assert numpy_path.stats["estimator"].endswith("NumPy)")
    np.testing.assert_allclose(compiled.image, numpy_path.image, rtol=1e-9, atol=1e-12)


def test_deterministic_on_any_thread_count_and_resumable(exercise_scene):
    scene, _ = exercise_scene
    strategy, _ = parse_lab_token(f"mis:{EXAMPLE}:PhongLobes")
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = render_lab(scene, strategy, RenderSettings(spp=4, seed=5))
    finally:
        numba.set_num_threads(threads)
    whole = render_lab(scene, strategy, RenderSettings(spp=4, seed=5))
    first = render_lab(scene, strategy, RenderSettings(spp=1, seed=5))
    rest = render_lab(scene, strategy, RenderSettings(spp=3, seed=5, first_sample=1), resume=first.accumulator)
    assert np.array_equal(one.image, whole.image)
    assert np.array_equal(whole.image, rest.image) and np.array_equal(whole.variance, rest.variance)


def test_a_failing_njit_technique_keeps_what_was_rendered(exercise_scene):
    scene, _ = exercise_scene
    jit = _module(TECHNIQUES)
    counting = jit.FailsLater(samples=10**12)
    render_lab(scene, LabStrategy((GuardedTechnique(counting, "FailsLater"),)), RenderSettings(spp=1, seed=1))
    per_pass = counting.data[0][0]
    failing = GuardedTechnique(jit.FailsLater(samples=1.5 * per_pass), "FailsLater")
    with pytest.raises(LabRenderError, match="ran out of luck") as info:
        render_lab(scene, LabStrategy((failing,)), RenderSettings(spp=8, seed=1))
    kept = info.value.result
    assert kept is not None and kept.counts.min() == 1 and np.isfinite(kept.image).all()
    assert "FailsLater.sample raised RuntimeError" in str(info.value)
