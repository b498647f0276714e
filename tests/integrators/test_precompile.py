"""Stages compiled in a helper process (integrators/precompile.py): what a helper saves is what the render loads."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from lightprobe.integrators import compile_helper, precompile

ROOT = Path(__file__).resolve().parents[2]


def test_a_helper_compiles_the_stage_the_render_then_loads(tmp_path):
    """In a fresh process with an empty kernel cache: a helper compiles the accumulation stage for the signature the
    render sends it, and the render's own compile of that stage then loads it from the cache (a cache hit, no miss):
    the types a helper is sent are the render's."""
    script = """
import json
import numpy as np
from lightprobe.integrators import pipeline, precompile
from lightprobe.integrators.accumulation import Accumulator
from lightprobe.integrators.schedule import pass_pixels
from lightprobe.integrators.wavefront import RenderSettings, _Pass, resolve
from lightprobe.geometry.raytracer import RayTracer
from lightprobe.demo import demo_scene
scene = demo_scene((8, 5))
arrays = scene.compile()
work = _Pass(scene, resolve(scene, RenderSettings(spp=1, adaptive=False)), arrays, RayTracer(arrays), 40, 1)
work.make_buffers()
records = work.records(Accumulator(40), pass_pixels(0, 1), 1, 0)
helpers = precompile.Helpers()
helpers.start(("accumulate",), precompile.record_types_pickled(records))
codes = [helper.wait(timeout=600) for helper in helpers.processes]
helpers.wait_for("accumulate")  # the helper claimed it: wait until it has said it saved it
saved, started = sorted(helpers.claims.saved), len(helpers.processes)
helpers.stop()
stage = pipeline.STAGES[pipeline.stage_id("accumulate")]
body = stage.body
body.compile(pipeline.body_signature(pipeline.record_types(records), stage.parameters))
print(json.dumps({"helpers": started, "codes": codes, "hits": sum(body._cache_hits.values()),
                  "misses": sum(body._cache_misses.values()), "saved": saved}))
"""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), precompile.ENVIRONMENT: "1"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, cwd=ROOT, env=env)
    found = json.loads(out.stdout.strip().splitlines()[-1])
    assert found == {"helpers": 1, "codes": [0], "hits": 1, "misses": 0, "saved": ["accumulate"]}


def test_each_body_is_claimed_by_one_process_and_a_claim_is_waited_for(tmp_path):
    """Whichever process claims a body first compiles it; the other's claim fails.  The render waits for a body a
    helper claimed until the helper reports it saved, or until no helper is left (then it compiles it itself)."""
    import threading
    import time

    first, second = precompile.Claims(str(tmp_path)), precompile.Claims(str(tmp_path))
    assert first.claim("setup") and not second.claim("setup") and not first.claim("setup")
    assert second.claim("finish")

    second.running = 1  # a helper that claimed "camera" and saves it a little later
    assert first.claim("camera") and not second.claim("camera")

    def saves():
        time.sleep(0.3)
        with second.changed:
            second.saved.add("camera")
            second.changed.notify_all()

    threading.Thread(target=saves).start()
    start = time.perf_counter()
    second.wait_for("camera")
    assert "camera" in second.saved and time.perf_counter() - start >= 0.25

    gone = precompile.Claims(str(tmp_path))  # no helper left: no wait, whoever claimed it
    start = time.perf_counter()
    gone.wait_for("setup")
    assert time.perf_counter() - start < 0.1


def test_how_many_helpers(monkeypatch):
    """Unset or 0: none (the Python API's default); a number, at most one per stage; auto: one per spare core, at
    most one per two stages; anything else: none."""
    monkeypatch.delenv(precompile.ENVIRONMENT, raising=False)
    assert precompile.helpers_wanted(9) == 0
    for given, stages, wanted in (("0", 9, 0), ("3", 9, 3), ("3", 2, 2), ("many", 9, 0)):
        monkeypatch.setenv(precompile.ENVIRONMENT, given)
        assert precompile.helpers_wanted(stages) == wanted
    monkeypatch.setenv(precompile.ENVIRONMENT, "auto")
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    assert precompile.helpers_wanted(9) == 4 and precompile.helpers_wanted(20) == 7
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    assert precompile.helpers_wanted(9) == 0


def test_a_render_keeps_the_record_types_for_the_next_renders_early_helpers(tmp_path, monkeypatch):
    """The pass records' pickled types, kept in the kernel cache by a render's warm-up, let the next render of a
    kind not yet compiled start its helpers before it builds its lights: for the stages of its plan, with those
    types; without the file, or with helpers off, or with every stage cached, none start early."""
    import pickle

    from lightprobe.demo import demo_scene
    from lightprobe.integrators import wavefront

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv(precompile.ENVIRONMENT, "1")
    started = []
    monkeypatch.setattr(
        precompile.Helpers, "start", lambda self, stages, signatures: started.append((stages, signatures))
    )
    scene, settings = demo_scene((8, 5)), wavefront.RenderSettings(spp=1)
    assert precompile.known_record_types() is None
    wavefront._start_helpers_early(scene, settings, precompile.Helpers())
    assert started == []  # nothing kept yet

    precompile.save_record_types(pickle.dumps(("types",)))
    assert pickle.loads(precompile.known_record_types()) == ("types",)
    monkeypatch.setattr(wavefront, "_stages_cached", lambda plan: False)
    wavefront._start_helpers_early(scene, settings, precompile.Helpers())
    assert started == [(wavefront.plan_for(scene, settings).stages(), pickle.dumps(("types",)))]

    monkeypatch.setattr(wavefront, "_stages_cached", lambda plan: True)
    wavefront._start_helpers_early(scene, settings, precompile.Helpers())
    monkeypatch.setattr(wavefront, "_stages_cached", lambda plan: False)
    monkeypatch.setenv(precompile.ENVIRONMENT, "0")
    wavefront._start_helpers_early(scene, settings, precompile.Helpers())
    assert len(started) == 1


def test_a_helper_takes_the_longest_compile_first():
    """The setup stage (the longest compile of the demo's plan) first, the rest from the last; ties keep that order."""
    stages = ("camera", "setup", "environment_samples_lanes", "finish", "analytic_shadows_lanes", "accumulate")
    assert precompile.largest_first(stages) == [
        "setup",
        "finish",
        "camera",
        "accumulate",
        "analytic_shadows_lanes",
        "environment_samples_lanes",
    ]


def test_an_empty_scene_has_the_pass_record_types_of_any_scene():
    """A prestarted helper compiles for an empty scene's record types before the render has its own: they must be
    the demo's and the many-light scene's, or its work would be for nothing."""
    import pickle

    from lightprobe.demo import demo_scene, many_lights_scene
    from lightprobe.geometry.raytracer import RayTracer
    from lightprobe.integrators import wavefront
    from lightprobe.integrators.accumulation import Accumulator
    from lightprobe.integrators.schedule import pass_pixels

    def types_of(scene):
        arrays = scene.compile()
        plan = wavefront.resolve(scene, wavefront.RenderSettings(spp=1, adaptive=False))
        work = wavefront._Pass(scene, plan, arrays, RayTracer(arrays), 40, 1)
        work.make_buffers()
        return pickle.loads(precompile.record_types_pickled(work.records(Accumulator(40), pass_pixels(0, 1), 1, 0)))

    empty = pickle.loads(compile_helper.empty_record_types())
    assert empty == types_of(demo_scene((8, 5))) == types_of(many_lights_scene(50, (8, 5)))


def test_a_prestarted_helper_compiles_its_first_stages_then_the_plan_it_is_sent(tmp_path):
    """In a fresh process with an empty kernel cache: a helper started before any scene compiles its speculative
    stage for an empty scene's record types, then waits; sent a plan (without types) it compiles the stages of it
    that nobody claimed, and reports each saved."""
    script = """
import json
from lightprobe.integrators import precompile
helpers = precompile.Helpers()
helpers.prestart(("accumulate",))
assert helpers.waiting and helpers.started
helpers.wait_for("accumulate")
first = sorted(helpers.claims.saved)
assert helpers.claim("environment_radiance_lanes")  # the render's: the helper skips it
helpers.start(("accumulate", "environment_radiance", "environment_radiance_lanes"), None)
codes = [helper.wait(timeout=600) for helper in helpers.processes]
helpers.wait_for("environment_radiance")
print(json.dumps({"first": first, "saved": sorted(helpers.claims.saved), "codes": codes}))
helpers.stop()
"""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), precompile.ENVIRONMENT: "1"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, cwd=ROOT, env=env)
    found = json.loads(out.stdout.strip().splitlines()[-1])
    assert found == {"first": ["accumulate"], "saved": ["accumulate", "environment_radiance"], "codes": [0]}


def test_prestart_only_where_the_stage_loop_is_not_compiled(monkeypatch):
    """Nothing is prestarted with helpers off, or where the stage loop is in the cache (the machine has rendered);
    the render then takes new helpers, not yet started."""
    from lightprobe import _numba

    spawned = []
    monkeypatch.setattr(precompile.Helpers, "prestart", lambda self: spawned.append(self))
    monkeypatch.setenv(precompile.ENVIRONMENT, "0")
    precompile.prestart()
    monkeypatch.setenv(precompile.ENVIRONMENT, "1")
    monkeypatch.setattr(_numba, "is_cached", lambda *kernels: True)
    precompile.prestart()
    assert spawned == []
    taken = precompile.take_prestarted()
    assert not taken.started and not taken.waiting
