"""The stage table: every stage a plan can pick is in it, each vector stage's scalar twin is too, and a plan
picks each concern's stage once, in the estimator's order."""

import itertools
from dataclasses import fields

import pytest

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


def test_every_plan_runs_known_stages_in_the_estimators_order():
    order = ["camera", "setup", "samples", "bsdf rays", "finish", "shadows", "accumulate"]

    def concern(name):
        if name.startswith("camera"):
            return "camera"
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
        assert "finish" in names and "setup" in names


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
