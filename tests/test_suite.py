"""The benchmark suite (benchmarks/suite.py, issue 57) without Mitsuba: every suite scene builds and renders, the
unoccluded-power helper gives a known answer, and the table's ratios, minimum and geometric mean are right."""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
from pathlib import Path
from types import SimpleNamespace

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
    assert NAMES[:3] == ("sky", "area", "many")  # the test references' scenes are unchanged (sunsky joined them)
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


@pytest.mark.parametrize("bias", [1.0, 1.02])
def test_the_spread_between_seeds_measures_each_configurations_variance_and_its_bias_against_the_peer(tmp_path, bias):
    # --spread: no reference; synthetic images of known variance (lightprobe's sd 0.01, two Mitsuba configurations'
    # 0.03 and 0.05), four seeds each: relMSE within a few percent of sd^2 / (truth^2 + 0.01); the pooled z small
    # for an unbiased lightprobe and large for one 2 % too bright; the image files removed once measured
    suite = _suite_module()
    rng = np.random.default_rng(11)
    truth = rng.uniform(0.2, 1.0, (48, 64, 3))
    rows = []
    for renderer, config, sd in (("lightprobe", "defaults", 0.01), ("mitsuba", "a", 0.03), ("mitsuba", "b", 0.05)):
        files = []
        for seed in range(4):
            image = truth * (bias if renderer == "lightprobe" else 1.0) + rng.normal(0, sd, truth.shape)
            files.append(str(tmp_path / f"{renderer}_{config}_{seed}.npy"))
            np.save(files[-1], image)
        rows.append({"renderer": renderer, "config": config, "spp": 64, "seconds": 2.0, "images": files, "sd": sd})
    measured = suite.spread_metrics(rows)
    for row in measured:
        expected = np.mean(row["sd"] ** 2 / (truth**2 + 0.01))
        assert row["relmse"] == pytest.approx(expected, rel=0.05)
        assert row["efficiency"] == pytest.approx(1.0 / (row["relmse"] * 2.0))
        assert "images" not in row
    z = measured[0]
    assert "z_image" in z and "z_image" not in measured[1]
    if bias == 1.0:
        assert abs(z["z_image"]) < 4 and z["z_blocks_over4"] < 0.05
    else:
        assert abs(z["z_image"]) > 10
    assert not list(tmp_path.iterdir())


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
    # a later log of one scene at another spp alone adds its rows and keeps the earlier spp's
    later = log(tmp_path / "later.log", "ddddddd", [
        _row("mitsuba", "a", 64, "multijitter 1+1", 0.01, 1.0), _row("lightprobe", "a", 64, "defaults", 0.0025, 1.0),
    ])  # fmt: skip
    args.table_from, args.json = [old, new, later], str(tmp_path / "table.json")
    assert suite._table_from(args) == 0
    text = capsys.readouterr().out
    assert "**5.00x**" in text and "**2.00x**" in text and "**4.00x**" in text
    commit = json.loads((tmp_path / "table.json").read_text())["header"]["commit"]
    assert "a lightprobe 16 spp" in commit and "a lightprobe 64 spp" in commit and "b lightprobe)" in commit
    args.json = None
    args.table_from = [old, log(tmp_path / "small.log", "ccccccc", [], resolution=(64, 48))]
    with pytest.raises(SystemExit, match="resolution"):
        suite._table_from(args)


# ------------------------------------------------------------------ the Cycles peer's translation (no bpy needed)


def _cycles_module():
    spec = importlib.util.spec_from_file_location("cycles_scene", SUITE_SCRIPT.parent / "cycles_scene.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _triangle_areas(vertices, faces):
    v = np.asarray(vertices)[np.asarray(faces)]
    return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]) / 2  # area-weighted normals (winding)


@pytest.mark.parametrize("name", ["area", "ceiling", "dome", "window", "building", "glossy", "city"])
def test_cycles_export_keeps_every_emitters_side_radiance_and_power_and_every_surface(name):
    """The file the Cycles worker builds from holds every emitter facing its described side with its radiance (one
    level per distinct radiance), the same emitted power per radiance, the same area of every material's surfaces
    and the same spheres as the description."""
    cs = _cycles_module()
    desc = describe(name)
    meta, arrays = cs.flatten(desc)
    batches = [o for o in desc["objects"] if o["shape"] == "rectangles"]  # the city's 100,000 windows, as arrays
    objects = [o for o in desc["objects"] if o["shape"] != "rectangles"]

    def vector_area(o):  # the area-weighted normal of a flat described shape
        if o["shape"] == "rectangle":
            return np.cross(o["edge_u"], o["edge_v"])[None, :]
        return _triangle_areas(o["vertices"], o["faces"])

    # emitters: per radiance, the summed area-weighted normal (their side) and the summed area (their power)
    radiances, normals = [], []  # one row per flat emitter's face (a rectangle, a triangle, a batch's rectangle)
    for o in objects:
        if "emission" in o and o["shape"] != "sphere":
            n = vector_area(o)
            radiances.append(np.broadcast_to(np.broadcast_to(o["emission"], 3), n.shape))
            normals.append(n)
    for batch in batches:
        radiances.append(batch["levels"][batch["level"]])
        normals.append(np.cross(batch["edges_u"], batch["edges_v"]))
    want_normal, want_area = {}, {}
    if normals:
        keys, which = np.unique(np.round(np.concatenate(radiances), 9), axis=0, return_inverse=True)
        n = np.concatenate(normals)
        summed = np.zeros((len(keys), 3))
        area = np.zeros(len(keys))
        np.add.at(summed, which.ravel(), n)
        np.add.at(area, which.ravel(), np.linalg.norm(n, axis=1))
        for i, key in enumerate(map(tuple, keys)):
            want_normal[key], want_area[key] = summed[i], area[i]
    if want_area:
        n = _triangle_areas(arrays["emitters_vertices"], arrays["emitters_faces"])
        levels = arrays["emitters_levels"][arrays["emitters_level"]]
        assert len(arrays["emitters_levels"]) == len(want_area)  # one material per distinct radiance
        for key, area in want_area.items():
            mine = np.all(np.isclose(levels, key, rtol=1e-12), axis=1)
            assert np.linalg.norm(n[mine], axis=1).sum() == pytest.approx(area, rel=1e-9)
            assert np.allclose(n[mine].sum(axis=0), want_normal[key], rtol=1e-9, atol=1e-9 * area)
    else:
        assert "emitters_vertices" not in arrays
    spheres = [o for o in objects if o["shape"] == "sphere"]
    assert len(meta["sphere_lights"]) == sum("emission" in o for o in spheres)
    assert len(meta["spheres"]) == sum("emission" not in o for o in spheres)
    # surfaces: every (material, sidedness)'s area and area-weighted normal (a batch's rectangles all emit)
    want = {}
    for o in objects:
        if "emission" in o or o["shape"] == "sphere":
            continue
        key = (o["material"], bool(o.get("two_sided", False)))
        n = vector_area(o)
        a, s = want.get(key, (0.0, 0.0))
        want[key] = (a + np.linalg.norm(n, axis=1).sum(), s + n.sum(axis=0))
    got = {}
    for i, s in enumerate(meta["surfaces"]):
        key = (s["material"], s["two_sided"])
        n = _triangle_areas(arrays[f"surface{i}_vertices"], arrays[f"surface{i}_faces"])
        a, t = got.get(key, (0.0, 0.0))
        got[key] = (a + np.linalg.norm(n, axis=1).sum(), t + n.sum(axis=0))
        assert s["smooth"] == (f"surface{i}_normals" in arrays)
    assert got.keys() == want.keys()
    for key, (area, normal) in want.items():
        assert got[key][0] == pytest.approx(area, rel=1e-9)
        assert np.allclose(got[key][1], normal, rtol=1e-9, atol=1e-9 * area)


def test_cycles_frame_camera_and_sphere_light_conventions():
    """Y up -> Blender's Z up is a rotation; Blender's camera looks along its local -Z at the target with the
    description's right (forward x up) as its +X; a point light's power gives the sphere's radiance back."""
    cs = _cycles_module()
    rot = cs.to_blender(np.eye(3))
    assert np.allclose(rot @ rot.T, np.eye(3)) and np.linalg.det(rot) == pytest.approx(1.0)
    assert np.allclose(cs.to_blender([0.0, 1.0, 0.0]), [0.0, 0.0, 1.0])  # up is +Z
    origin, target = np.array([0.4, 2.2, 6.4]), np.array([0.0, 0.5, 0.0])
    m = cs.camera_matrix(origin, target)
    local = np.linalg.inv(m) @ np.append(cs.to_blender(target), 1.0)
    assert local[0] == pytest.approx(0.0, abs=1e-12) and local[1] == pytest.approx(0.0, abs=1e-12) and local[2] < 0
    forward = (target - origin) / np.linalg.norm(target - origin)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    local = np.linalg.inv(m) @ np.append(cs.to_blender(origin + forward + 0.1 * right), 1.0)
    assert local[0] > 0  # right of the view is the image's right (Mitsuba's look_at)
    assert np.linalg.inv(m)[:3, :3] @ cs.to_blender([0.0, 1.0, 0.0]) @ [0.0, 1.0, 0.0] > 0  # up is up in the image
    power = cs.sphere_light_power(0.12, [60.0, 45.0, 30.0])
    assert np.allclose(power / (4 * math.pi * math.pi * 0.12**2), [60.0, 45.0, 30.0])


def test_cycles_export_refuses_what_it_does_not_translate(tmp_path):
    cs = _cycles_module()
    with pytest.raises(cs.NotTranslated):
        cs.flatten({"camera": {}, "environment": None, "materials": {}, "objects": [{"shape": "gltf", "file": "x"}]})
    suite = _suite_module()
    with pytest.raises(ValueError, match="peer kit"):  # NotTranslated of the suite's own import of cycles_scene
        suite.export_cycles_scene(tmp_path, "peer", (16, 12))
    out = suite.export_cycles_scene(tmp_path, "window", (16, 12))  # a procedural sky: written beside as an image
    meta, _ = cs.load(out)
    assert meta["resolution"] == [16, 12] and Path(meta["environment"]["file"]).exists()
    assert suite.cycles_python("none")[0] is None and suite.cycles_python(str(tmp_path / "no-python"))[0] is None


def test_the_best_peer_may_be_cycles_but_never_one_whose_reference_fails_the_floor_rule():
    suite = _suite_module()
    rows = [
        _row("mitsuba", "a", 16, "multijitter 1+1", 0.01, 1.0),  # 100
        _row("cycles", "a", 16, "cycles tree 1+1", 0.002, 1.0) | {"floor_ratio": 0.01},  # 500: the best
        _row("lightprobe", "a", 16, "defaults", 0.001, 1.0),  # 1000: ratio 2
        _row("mitsuba", "b", 16, "multijitter 1+1", 0.01, 1.0),  # 100: the best judged
        _row("cycles", "b", 16, "cycles tree 1+1", 0.001, 1.0) | {"floor_ratio": 0.5},  # its reference too noisy
        _row("lightprobe", "b", 16, "defaults", 0.001, 1.0),  # ratio 10
    ]
    by_scene = {s["scene"]: s for s in suite.summarise(rows, {})}
    assert by_scene["a"]["best"]["config"] == "cycles tree 1+1" and by_scene["a"]["ratio"] == pytest.approx(2.0)
    assert by_scene["b"]["best"]["config"] == "multijitter 1+1" and by_scene["b"]["ratio"] == pytest.approx(10.0)
    assert "1e+03*" in suite.peer_table(suite.summarise(rows, {}))  # listed, marked
    assert "cycles tree 1+1" in suite.cycles_table(rows)


def test_reference_agreement_finds_a_two_percent_difference_and_passes_an_equal_image():
    suite = _suite_module()
    rng = np.random.default_rng(4)
    truth = rng.uniform(0.2, 1.0, (48, 64, 3))
    var = np.full(truth.shape, 1e-6)
    a = {"mean": truth + rng.normal(0, 1e-3, truth.shape), "variance": var}
    b = {"mean": truth + rng.normal(0, 1e-3, truth.shape), "variance": var}
    mask = np.zeros((48, 64), bool)
    mask[:8] = True
    same = suite.reference_agreement(a, b, mask)
    assert abs(same["z_image"]) < 4 and same["z_blocks_over4"] < 0.05
    assert same["relmse"] == pytest.approx(same["noise_relmse"], rel=0.2) and same["lambertian"]["pixels"] == 40 * 64
    off = suite.reference_agreement({"mean": a["mean"] * 1.02, "variance": var}, b, mask)
    assert abs(off["z_image"]) > 10 and off["mean_ratio"][0] == pytest.approx(1.02, abs=1e-3)


@pytest.mark.parametrize("name", ["area", "many"])
def test_rectangle_lights_as_a_mesh_keep_their_corners_and_radiance(name):
    # the area scene gives its vectors as lists (whose + concatenates): the mesh must still have each rectangle's
    # four corners and its radiance on both of its triangles, so the mesh's lights emit the rectangles' power
    rects = [o for o in build(name).objects if isinstance(o.shape, Rectangle) and o.emission is not None]
    (mesh,) = [o for o in build(name, lights_as_mesh=True).objects if o.name == "lights"]
    corners = np.array([[r.shape.origin, r.shape.origin + r.shape.edge_u] for r in rects], np.float64)
    vertices = np.asarray(mesh.shape.vertices, np.float64).reshape(len(rects), 4, 3)
    assert np.allclose(vertices[:, :2], corners)
    power = sum(np.linalg.norm(np.cross(r.shape.edge_u, r.shape.edge_v)) * np.mean(r.emission) for r in rects)
    v = np.asarray(mesh.shape.vertices, np.float64)[np.asarray(mesh.shape.faces)]
    areas = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    assert np.isclose(np.sum(areas * np.asarray(mesh.emission, np.float64).mean(axis=1)), power)


def test_a_mitsuba_worker_aborting_in_an_old_llvm_stops_the_run_in_one_line_and_other_failures_keep_their_output(
    monkeypatch, tmp_path
):
    suite = _suite_module()
    crash = "LLVM ERROR: Cannot select: 0x7f03743a1dc8: f32 = fminimum 0x1, 0x2\n" + "  0x7f: v16f32 = fma\n" * 40
    failure = {"stderr": crash}
    monkeypatch.setattr(
        suite.subprocess,
        "run",
        lambda *a, **k: subprocess.CompletedProcess(a, returncode=-6, stdout="", stderr=failure["stderr"]),
    )
    args = SimpleNamespace(seeds=2, resolution=[32, 24], cache=tmp_path, lightprobe_option=[])
    with pytest.raises(SystemExit) as stopped:
        suite._run(args, "mitsuba", "area", "--spp", "16")
    message = str(stopped.value)
    assert "\n" not in message and "mitsuba worker on area" in message
    assert "apt-get install libllvm19" in message and "DRJIT_LIBLLVM_PATH" in message
    with pytest.raises(RuntimeError, match="pilot worker on area failed"):  # lightprobe's pilot: not Mitsuba's LLVM
        suite._run(args, "pilot", "area", "--spp", "16")
    failure["stderr"] = "Traceback (most recent call last):\nValueError: a scene the worker cannot build"
    with pytest.raises(RuntimeError, match="ValueError: a scene the worker cannot build"):
        suite._run(args, "mitsuba", "area", "--spp", "16")


@pytest.mark.parametrize("present, warned", [(("libLLVM-15.so", "libLLVM.so.15"), True), (("libLLVM-19.so",), False)])
def test_mitsuba_is_pointed_at_libllvm_19_and_a_machine_with_only_an_older_one_is_told_the_remedy(
    monkeypatch, tmp_path, capsys, present, warned
):
    references = _suite_module()._mitsuba_references()
    for name in present:
        (tmp_path / name).write_bytes(b"")
    monkeypatch.setattr(references, "_LIBRARY_FOLDERS", (str(tmp_path),))
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "")  # so that the path the function sets is undone after the test
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH")
    references._prefer_llvm19()
    said = capsys.readouterr().err
    if warned:
        assert "DRJIT_LIBLLVM_PATH" not in os.environ
        assert said.count("\n") == 1 and "only libLLVM 15 found" in said and "apt-get install libllvm19" in said
    else:
        assert os.environ["DRJIT_LIBLLVM_PATH"] == str(tmp_path / "libLLVM-19.so")
        assert said == ""
