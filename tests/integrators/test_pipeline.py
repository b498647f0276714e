"""The stage table: every stage a plan can pick is in it, each vector stage's scalar twin is too, and a plan
picks each concern's stage once, in the estimator's order."""

import itertools
from dataclasses import fields

import pytest
from numba import types

from lightprobe.integrators import pipeline

NAMES = [stage.name for stage in pipeline.STAGES]
FLAGS = [f.name for f in fields(pipeline.Plan)]


def _plans():
    for values in itertools.product((False, True), repeat=len(FLAGS)):
        yield pipeline.Plan(**dict(zip(FLAGS, values, strict=True)))


def test_stage_names_are_unique_and_twins_are_stages():
    assert len(set(NAMES)) == len(NAMES)
    for stage in pipeline.STAGES:
        if stage.twin is not None:
            assert stage.twin in NAMES, stage.name
            twin = pipeline.STAGES[pipeline.stage_id(stage.twin)]
            assert twin.twin is None, f"{stage.twin} is a twin with a twin"
        assert pipeline.stage_id(stage.name) == NAMES.index(stage.name)


def test_each_stage_body_takes_the_records_it_uses_and_no_more_than_nine_arguments():
    """A body's signature is the declaration of its data: names of the pass records in their order, then the loop's
    facts; the widest (the setup stage and the BSDF rays' weighing) read six records and the claimed items."""
    for stage in pipeline.STAGES:
        names = stage.parameters
        assert names[-2:] == ("lo", "hi"), stage.name
        assert set(names) <= set(pipeline.RECORDS + pipeline.CLAIM), stage.name
        assert len(names) <= 9, (stage.name, names)
    assert pipeline.STAGES[pipeline.stage_id("environment_radiance")].parameters == ("env", "slots", "lo", "hi")
    assert "acc" not in pipeline.STAGES[pipeline.stage_id("setup")].parameters
    assert pipeline.STAGES[pipeline.stage_id("accumulate")].parameters == ("c", "cams", "slots", "acc", "lo", "hi")


@pytest.mark.parametrize(
    "signature", ["slots, env, lo, hi", "env, slots", "env, light_table, lo, hi", "env, slots, lo, hi, worker"]
)
def test_a_body_whose_parameters_are_not_records_in_order_is_refused_by_name(signature):
    namespace = {}
    exec(f"def odd_stage({signature}):\n    pass\n", namespace)
    with pytest.raises(TypeError, match="odd_stage"):
        pipeline.body_parameters(namespace["odd_stage"])


def test_the_stage_loop_calls_each_body_with_the_records_it_names():
    """One call site per parameter list, each passing the records the bodies of that list name, in their order;
    every stage's list is one of them."""
    source = pipeline.stage_loop_source()
    assert "call_body(body, (env, slots, lo, hi))" in source  # environment_radiance
    assert "call_body(body, (s, lights, c, cams, slots, lo, hi))" in source  # finish
    for stage in pipeline.STAGES:
        i = pipeline.PATTERNS.index(stage.parameters)
        assert f"pattern == {i}:" in source and f"call_body(body, ({', '.join(stage.parameters)}))" in source
    assert source.count("call_body(") == len(pipeline.PATTERNS) == len(set(pipeline.PATTERNS))
    assert source.count("claim_range(counter, n)") == 2  # a first claim and the next


def test_every_plan_runs_known_stages_in_the_estimators_order():
    order = ["camera", "setup", "samples", "bsdf rays", "finish", "shadows", "accumulate"]

    def concern(name):
        if name.startswith("camera"):
            return "camera"
        if name.startswith("setup"):
            return "setup"
        if name in ("light_samples",) or name.startswith("environment_samples"):
            return "samples"
        if name.startswith(("environment_coords", "environment_radiance", "infinite_lights", "nearest_", "what_")):
            return "bsdf rays"
        if name.endswith("shadows") or "shadows_" in name:
            return "shadows"
        return name

    for plan in _plans():
        names = plan.stages()
        assert all(n in NAMES for n in names), (plan, names)
        assert len(set(names)) == len(names), names
        ranks = [order.index(concern(n)) for n in names]
        assert ranks == sorted(ranks), (plan, names)
        assert names[0].startswith("camera") and names[-1] == "accumulate"
        assert "finish" in names and ("setup_textured" if plan.textured else "setup") in names


@pytest.mark.parametrize(
    "vector, scalar_flag, scene_flags",
    [
        ("camera", "lanes", ()),
        ("analytic_shadows_lanes", "lanes", ()),
        ("analytic_shadows_lanes", "lanes", ("bounded_lights",)),
        ("nearest_analytic_lanes", "lanes", ("bounded_lights", "emissive_surfaces")),
    ],
)
def test_a_vector_stage_falls_back_to_its_twin(vector, scalar_flag, scene_flags):
    """Without the vector intrinsics (``lanes`` false) a plan runs the twin the table names; with them, the vector
    stage serves scenes lit by the environment and by area lights alike."""
    twin = pipeline.STAGES[pipeline.stage_id(vector)].twin
    base = dict.fromkeys(FLAGS, False) | dict.fromkeys(scene_flags, True)
    assert vector in pipeline.Plan(**{**base, scalar_flag: True}).stages()
    without = pipeline.Plan(**base).stages()
    assert vector not in without and twin in without


def test_a_stage_compiles_its_own_body_and_no_others(tmp_path):
    """In a fresh process with an empty kernel cache, running the accumulation stage compiles its body and the
    stage loop and no other stage's body (the loop over every stage compiled all 22 bodies at a first render:
    decisions.md 104)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = """
import json
import numpy as np
from lightprobe.integrators import pipeline
from tests.integrators.stages import records
c = records.constants(1, n_bsdf=0, pixels=np.arange(4), spp_pass=1)
records.run("accumulate", records.records(c, records.cameras(4), records.slots(4)), threads=1)
print(json.dumps([stage.name for stage in pipeline.STAGES if stage.body.signatures]
                 + ["run_stage"] * len(pipeline.run_stage.signatures)))
"""
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, cwd=root, env=env)
    compiled = json.loads(out.stdout.strip().splitlines()[-1])
    assert compiled == ["accumulate", "run_stage"], compiled


def test_the_setup_stage_of_a_scene_without_textures_has_no_texture_code():
    """The setup stage's texture step is chosen at compile time: with a constant False it is empty (no texture
    lookup is typed or compiled), with True it applies the material's textures."""

    from lightprobe.integrators.stages import setup

    args = (types.int64,) * 6
    without = setup._textures_if_overload(types.literal(False), *args)
    with_textures = setup._textures_if_overload(types.literal(True), *args)
    assert "apply_textures" not in without.__code__.co_names
    assert "apply_textures" in with_textures.__code__.co_names


def test_one_stage_loop_serves_every_plan():
    """The loop reaches the bodies through their addresses: renders of two plans (the demo's, lit by a sky map and
    a sun, and the many-light scene's) compile it once, for the one signature of the pass records, and each
    render's bodies are then in the cache."""
    from lightprobe.demo import demo_scene
    from lightprobe.integrators import wavefront
    from lightprobe.reference_scenes import build

    settings = wavefront.RenderSettings(spp=4, threads=2)
    plans = set()
    for scene in (demo_scene((16, 10)), build("many", resolution=(16, 10), lights=200)):
        result = wavefront.render(scene, settings)
        assert result.image.max() > 0
        assert wavefront.kernels_cached(scene, settings)
        plans.add(wavefront.plan_for(scene, settings).stages())
    assert len(plans) == 2
    assert len(pipeline.run_stage.signatures) == 1


def test_a_function_without_a_c_entry_is_refused_by_name():
    """The loop calls a body through its C entry; a function compiled without one is refused, naming it, rather
    than called at address 0."""
    from numba import njit

    @njit(no_cfunc_wrapper=True)
    def entryless(x):
        return x + 1

    entryless(1)
    with pytest.raises(RuntimeError, match="entryless was compiled without a C entry"):
        pipeline.entry_address(next(iter(entryless.overloads.values())))
