"""The benchmark suite (benchmarks/suite.py, issue 57) without Mitsuba: every suite scene builds and renders, the
unoccluded-power helper gives a known answer, and the table's ratios, minimum and geometric mean are right."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.shapes import Rectangle
from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.reference_scenes import NAMES, SUITE, build, describe, unavailable, unoccluded_power_fraction
from lightprobe.scene import Scene

SUITE_SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "suite.py"


def _suite_module():
    spec = importlib.util.spec_from_file_location("suite_benchmark", SUITE_SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_suite_names_nine_scenes_and_keeps_the_references():
    assert NAMES == ("sky", "area", "many")  # the test references' scenes are unchanged
    assert len(SUITE) == len(set(SUITE)) >= 9
    assert {"peer", "area", "ceiling", "dome", "window", "building", "gltf", "glossy", "city"} <= set(SUITE)


@pytest.mark.parametrize("name", SUITE)
def test_every_suite_scene_builds_and_renders_finite(name):
    reason = unavailable(name)
    if reason is not None:
        pytest.skip(reason)
    scene = build(name, resolution=(16, 12))
    result = render(scene, RenderSettings(spp=1, seed=3))
    assert result.image.shape == (12, 16, 3)
    assert np.all(np.isfinite(result.image)) and np.all(np.isfinite(result.variance))
    assert result.image.max() > 0.0


def test_suite_scenes_have_the_lights_they_promise():
    def emitters(desc):
        return sum(o["level"].size if o["shape"] == "rectangles" else "emission" in o for o in desc["objects"])

    assert emitters(describe("ceiling")) == 2000
    assert emitters(describe("city")) == 100_000
    assert 200 <= emitters(describe("dome")) <= 500
    assert emitters(describe("building")) >= 6 * 16
    city = next(o for o in describe("city")["objects"] if o["shape"] == "rectangles")
    assert city["levels"].shape == (16, 3) and set(np.unique(city["level"])) <= set(range(16))
    # every window faces out of its building: its normal points away from the box it stands in front of
    normals = np.cross(city["edges_u"], city["edges_v"])
    assert np.allclose(np.abs(normals).sum(axis=1), 0.96)  # 0.8 m x 1.2 m, axis-aligned


def test_the_window_room_is_closed_but_for_its_window():
    """Rays from inside the room in every direction hit the room, except those through the window opening."""
    scene = build("window", resolution=(8, 6))
    from lightprobe.geometry.raytracer import RayTracer

    rng = np.random.default_rng(5)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to([0.0, 1.3, 1.0], d.shape)
    tracer = RayTracer(scene.compile())
    try:
        t, *_ = tracer.intersect(o, d)
    finally:
        tracer.close()
    escaped = ~np.isfinite(t)
    assert escaped.any()
    # an escaping ray crosses the plane z = -3 inside the opening
    s = (-3.0 - 1.0) / d[escaped, 2]
    p = o[escaped] + s[:, None] * d[escaped]
    assert np.all(s > 0)
    assert np.all((np.abs(p[:, 0]) <= 0.8 + 1e-9) & (p[:, 1] >= 0.9 - 1e-9) & (p[:, 1] <= 2.1 + 1e-9))


def test_unoccluded_power_fraction_one_of_two_equal_lights_hidden():
    """Two equal lights facing down over a ground; a wide opaque sheet between the upper one and the ground hides
    it from every point the camera sees, and nothing hides the lower one: exactly half the power is unoccluded."""
    camera = Camera([2.0, 1.0, 0.0], [4.0, 0.0, 0.0], fov=30.0, fov_axis="x", resolution=(24, 16))
    scene = Scene(camera)
    scene.add(Rectangle([-50.0, 0.0, -50.0], [0.0, 0.0, 100.0], [100.0, 0.0, 0.0]), Lambert(0.5), name="ground")
    down = ([0.2, 0.0, 0.0], [0.0, 0.0, 0.2])  # edge_u x edge_v = -Y
    scene.add(Rectangle([2.9, 2.0, -0.1], *down), emission=5.0, name="lower light")
    scene.add(Rectangle([2.9, 4.0, -0.1], *down), emission=5.0, name="upper light")
    scene.add(Rectangle([-50.0, 3.0, -50.0], [100.0, 0.0, 0.0], [0.0, 0.0, 100.0]), Lambert(0.5), name="sheet")
    assert unoccluded_power_fraction(scene, stride=2) == pytest.approx(0.5, abs=1e-12)
    # without the sheet, both lights reach every visible point
    scene.objects.pop()
    assert unoccluded_power_fraction(scene, stride=2) == pytest.approx(1.0, abs=1e-12)


def test_the_building_hides_most_of_its_light():
    share = unoccluded_power_fraction(build("building", resolution=(80, 60)), stride=4)
    assert 0.02 < share < 0.25


def _row(renderer, scene, spp, config, relmse, seconds):
    return {"renderer": renderer, "scene": scene, "spp": spp, "config": config, "relmse": relmse,
            "seconds": seconds, "efficiency": 1.0 / (relmse * seconds)}  # fmt: skip


def test_the_table_takes_the_best_peer_and_the_minimum_and_geometric_mean_of_the_ratios():
    suite = _suite_module()
    rows = [
        _row("mitsuba", "a", 16, "independent 1+1", 0.01, 1.0),  # efficiency 100
        _row("mitsuba", "a", 16, "multijitter 1+1", 0.005, 1.0),  # 200: the best peer
        _row("lightprobe", "a", 16, "defaults", 0.001, 1.25),  # 800: ratio 4
        _row("mitsuba", "b", 16, "multijitter 4+4", 0.01, 0.5),  # 200
        _row("lightprobe", "b", 16, "defaults", 0.01, 1.0),  # 100: ratio 0.5
        _row("mitsuba", "c", 16, "multijitter 1+1", 0.01, 1.0),  # 100
        _row("lightprobe", "c", 16, "defaults", 0.001, 1.0),  # 1000, but its reference's floor is too high
    ]
    references = {"a": {"floor": 1e-5}, "b": {"floor": 1e-4}, "c": {"floor": 2e-4}}
    summary = suite.summarise(rows, references)
    by_scene = {s["scene"]: s for s in summary}
    assert by_scene["a"]["best"]["config"] == "multijitter 1+1"
    assert by_scene["a"]["ratio"] == pytest.approx(4.0)
    assert by_scene["b"]["ratio"] == pytest.approx(0.5)
    assert by_scene["c"]["refused"] and by_scene["c"]["ratio"] is None  # floor 2e-4 > a tenth of 1e-3
    lo, geo = suite.ratio_stats([s["ratio"] for s in summary])
    assert lo == pytest.approx(0.5) and geo == pytest.approx(math.sqrt(4.0 * 0.5))
    assert suite.ratio_stats([None]) == (None, None)
    text = suite.table(summary, pixels=100)
    assert "refused (floor)" in text and "minimum 0.50x, geometric mean 1.41x over 2" in text


def test_pooled_z_is_small_for_an_unbiased_image_and_large_for_a_biased_one():
    suite = _suite_module()
    rng = np.random.default_rng(9)
    truth = rng.uniform(0.2, 1.0, (48, 64, 3))
    ref = {"mean": truth + rng.normal(0, 0.001, truth.shape), "variance": np.full(truth.shape, 1e-6), "spp": 4096}
    var = np.full(truth.shape, 1e-4)
    images = [truth + rng.normal(0, 0.01, truth.shape) for _ in range(2)]
    z = suite.pooled_z(images, [var, var], 64, ref)
    assert abs(z["z_image"]) < 4 and z["z_blocks_over4"] < 0.02
    biased = suite.pooled_z([x * 1.02 for x in images], [var, var], 64, ref)
    assert abs(biased["z_image"]) > 10


def test_write_docs_replaces_the_text_between_the_markers(tmp_path):
    suite = _suite_module()
    doc = tmp_path / "performance.md"
    doc.write_text(f"# head\n{suite.DOCS_BEGIN}\nold table\n{suite.DOCS_END}\ntail\n")
    suite.write_docs("new table", doc)
    assert doc.read_text() == f"# head\n{suite.DOCS_BEGIN}\nnew table\n{suite.DOCS_END}\ntail\n"
    assert suite.parse_options(["outline_control_variate=false", "light_sampler=power", "spp=4"]) == {
        "outline_control_variate": False,
        "light_sampler": "power",
        "spp": 4,
    }


def test_outline_variance_is_zero_off_and_inside_an_emitter_and_at_most_a_quarter_l2_on_its_edge():
    """The reference's variance floor at emitters' outlines: L^2 a (1 - a) per camera sample, a the share of the
    pixel the emitter covers; 0 where it covers all or none of a pixel."""
    suite = _suite_module()
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], fov=20.0, fov_axis="x", resolution=(16, 12))
    scene = Scene(camera)
    # a square light facing the camera (+Z), covering part of the view
    scene.add(Rectangle([-0.33, -0.27, 0.0], [0.61, 0.0, 0.0], [0.0, 0.5, 0.0]), emission=3.0, name="light")
    floor = suite.outline_variance(scene)
    assert floor.shape == (12, 16, 3)
    assert np.all(floor >= 0.0) and np.all(floor <= 9.0 / 4 + 1e-9)
    assert floor[0, 0, 0] == 0.0 and floor[6, 8, 0] == 0.0  # a corner sees nothing; the centre is inside the light
    assert (floor > 0.0).sum() >= 3 * 10  # the outline crosses pixels all around the light


def test_a_table_from_two_logs_takes_each_renderers_rows_from_the_last_log_that_has_them(tmp_path, capsys):
    """``--table-from old.log new.log``: a scene measured again after a change replaces its rows of the renderers
    measured again; the others keep theirs, and the table names the commit of each; logs of another resolution are
    refused."""
    import json

    suite = _suite_module()

    def log(path, commit, rows, resolution=(320, 240)):
        head = {"cores": 2, "spp": [16], "seeds": 2, "resolution": list(resolution), "lightprobe_options": {},
                "commit": commit, "date": "2026-11-29"}  # fmt: skip
        path.write_text("\n".join(json.dumps(x) for x in [head, *rows]) + "\n")
        return str(path)

    old = log(tmp_path / "old.log", "aaaaaaa", [
        _row("mitsuba", "a", 16, "multijitter 1+1", 0.01, 1.0), _row("lightprobe", "a", 16, "defaults", 0.001, 1.0),
        _row("mitsuba", "b", 16, "multijitter 1+1", 0.01, 1.0), _row("lightprobe", "b", 16, "defaults", 0.01, 1.0),
    ])  # fmt: skip
    new = log(tmp_path / "new.log", "bbbbbbb", [
        _row("lightprobe", "b", 16, "defaults", 0.005, 1.0), _row("lightprobe", "a", 16, "defaults", 0.002, 1.0),
    ])  # fmt: skip
    args = type("Args", (), {"table_from": [old, new], "write_docs": False, "json": None})()
    assert suite._table_from(args) == 0
    text = capsys.readouterr().out
    # a's and b's lightprobe rows are the new log's (5x, 2x), their Mitsuba rows the old one's
    assert "**5.00x**" in text and "**2.00x**" in text and "**10.00x**" not in text and "**1.00x**" not in text
    args.table_from = [old, log(tmp_path / "small.log", "ccccccc", [], resolution=(64, 48))]
    with pytest.raises(SystemExit, match="resolution"):
        suite._table_from(args)
