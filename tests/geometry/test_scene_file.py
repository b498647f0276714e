"""The TOML scene format: a full example loads; every mistake is one clear error naming file and place."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lightprobe.errors import SceneError
from lightprobe.images import write_image
from lightprobe.io.scene_file import load_scene
from lightprobe.scene import Scene

SCENE = """
[camera]
origin = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
fov = 35
resolution = [64, 48]

[environment]
file = "sky.exr"
scale = 2.0
rotation = 30.0

[materials.floor]
type = "lambert"
albedo = 0.5
[materials.red]
type = "plastic"
diffuse = [0.6, 0.15, 0.1]
alpha = 0.3
[materials.gold]
type = "conductor"
alpha = 0.3
material = "Au"
[materials.shiny]
type = "phong"
rho_d = 0.2
rho_s = 0.7
exponent = 200

[[objects]]
type = "mesh"
file = "meshes/box.obj"
material = "red"
transform = { scale = 0.5, rotate = [0, 1, 0, 30], translate = [0, 0.5, 0] }

[[objects]]
type = "sphere"
center = [1.2, 0.4, 0.5]
radius = 0.4
material = "gold"

[[objects]]
type = "ground"
size = 20
material = "floor"

[[objects]]
type = "rectangle"
origin = [-2, 0.01, -2]
edge_u = [0, 0, 1]
edge_v = [1, 0, 0]
material = "shiny"
two_sided = true

[render]
spp = 8
strategy = "env"
"""


@pytest.fixture
def scene_dir(tmp_path):
    write_image(tmp_path / "sky.exr", np.ones((8, 16, 3), np.float32))
    (tmp_path / "meshes").mkdir()
    trimesh.creation.box().export(tmp_path / "meshes" / "box.obj")
    panels = trimesh.Trimesh([[0, 2, 0], [1, 2, 0], [1, 2, 1], [0, 2, 1]], [[0, 1, 2], [0, 2, 3]], process=False)
    panels.export(tmp_path / "meshes" / "panels.ply")
    np.save(tmp_path / "meshes" / "panels.npy", np.array([[1.0, 2.0, 3.0], [0.5, 0.5, 0.5]]))
    (tmp_path / "scene.toml").write_text(SCENE)
    return tmp_path


def test_full_scene(scene_dir):
    scene, defaults = load_scene(scene_dir / "scene.toml")
    assert len(scene.objects) == 4 and set(scene.materials) == {"floor", "red", "gold", "shiny"}
    assert scene.environment.scale == 2.0
    assert defaults == {"spp": 8, "strategy": "env"}
    assert scene.camera.resolution == (64, 48)
    mesh = scene.objects[0].shape
    assert mesh.bounds[0][1] == pytest.approx(0.25)  # scaled by 0.5 and lifted by 0.5
    assert isinstance(load_scene(scene_dir / "scene.toml")[0], Scene)


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('material = "gold"', 'material = "silver"', "objects[1]: unknown material 'silver'"),
        ("radius = 0.4", "radius = -1", "objects[1]: sphere radius"),
        ('file = "meshes/box.obj"', 'file = "meshes/none.obj"', "none.obj: no such file"),
        ('file = "sky.exr"', 'file = "missing.exr"', "missing.exr: no such file"),
        ("fov = 35", "fov = 200", "[camera]: camera fov"),
        ("albedo = 0.5", "albedo = 1.5", "[materials.floor]: albedo"),
        ('type = "sphere"', 'type = "torus"', "unknown object type 'torus'"),
        ("exponent = 200", "exponent = 200\ncolour = 1", "unknown key(s) colour"),
        ("rotate = [0, 1, 0, 30]", "rotate = [0, 1, 0]", "rotate entries"),
        ("[render]", "[render]\nturbo = true", "[render]: unknown key(s) turbo"),
        ("scale = 2.0", 'scale = "big"', "scale must be a finite number"),
        ("[camera]", "[camera\n", "not valid TOML"),
    ],
)
def test_errors_name_file_and_place(scene_dir, old, new, message):
    assert old in SCENE
    _assert_one_error(scene_dir / "scene.toml", SCENE.replace(old, new, 1), message)


def _assert_one_error(path, text, message):
    """Loading ``text`` written to ``path`` is one SceneError line naming the file and containing ``message``."""
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    error = str(info.value)
    assert message in error and "scene.toml" in error, error
    assert "\n" not in error


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_scene(tmp_path / "nope.toml")


# --- every key, every wrong type: one SceneError naming the key -----------------------------------------------------
EXTRA_RENDER_KEYS = (
    'heuristic = "power"\nbsdf_samples = 1\nenv_samples = 1\nseed = 3\nmis_compensation = false\nsampler = "sobol"\n'
    "env_candidates = 2\n"
)
SKY = "[environment]\nsky = { sun_elevation = 35, sun_azimuth = 45, sun_diameter = 2.0, width = 64, height = 32 }\n"
STRING_KEYS = {
    "type",
    "material",
    "file",
    "strategy",
    "heuristic",
    "mapping",
    "fov_axis",
    "lookup",
    "pdf",
    "pdf_weights",
    "estimator",
    "name",
}
WRONG_VALUES = ['"x"', '[1, "a"]', "true", "{ a = 1 }", "-1", "nan"]


LIGHTS = """
[[lights]]
type = "point"
position = [2.0, 3.0, 1.0]
intensity = 40.0
intensity_scale = 1.5

[[lights]]
type = "spot"
position = [0.0, 4.0, 2.0]
target = [0.0, 0.0, 0.0]
intensity = [60.0, 55.0, 50.0]
cone_angle = 25.0
falloff_start = 20.0

[[lights]]
type = "directional"
direction = [-0.3, -1.0, 0.2]
irradiance = [3.0, 2.8, 2.5]
angle = 0.53
irradiance_scale = 2.0
"""


def test_point_spot_and_directional_lights(scene_dir):
    from lightprobe.emitters.directional import DirectionalLight
    from lightprobe.emitters.kinds import LIGHT_DIRECTIONAL, LIGHT_ENVIRONMENT, LIGHT_POINT, LIGHT_SPOT
    from lightprobe.emitters.punctual import PointLight, SpotLight

    path = scene_dir / "scene.toml"
    path.write_text(SCENE + LIGHTS)
    scene, _ = load_scene(path)
    point, spot, sun = scene.lights
    assert type(point) is PointLight and np.allclose(point.radiance, 60.0) and np.allclose(point.position, [2, 3, 1])
    assert type(spot) is SpotLight and spot.cone_angle == 25.0 and spot.falloff_start == 20.0
    np.testing.assert_allclose(spot.axis, -np.array([0.0, 4.0, 2.0]) / np.sqrt(20.0))
    assert type(sun) is DirectionalLight and sun.angle == 0.53
    np.testing.assert_allclose(sun.irradiance, [6.0, 5.6, 5.0])
    np.testing.assert_allclose(sun.direction, np.array([-0.3, -1.0, 0.2]) / np.linalg.norm([-0.3, -1.0, 0.2]))
    # bounded lights first, then the infinite ones: the directional light, the environment last
    kinds = scene.light_table().kind.tolist()
    assert kinds == [LIGHT_POINT, LIGHT_SPOT, LIGHT_DIRECTIONAL, LIGHT_ENVIRONMENT]
    assert "1 point light + 1 spot light + 1 directional light" in scene.summary()
    # a scene lit by a lamp alone needs no environment
    path.write_text(SCENE.replace('[environment]\nfile = "sky.exr"\nscale = 2.0\nrotation = 30.0\n', "") + LIGHTS)
    assert load_scene(path)[0].environment is None


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('type = "point"', 'type = "area"', "lights[0]: unknown light type 'area'"),
        ("intensity = 40.0\n", "", "lights[0]: missing required key 'intensity'"),
        ("target = [0.0, 0.0, 0.0]", "target = [0.0, 4.0, 2.0]", "lights[1]: spot light: target must differ"),
        ("cone_angle = 25.0", "cone_angle = 95.0", "lights[1]: cone_angle"),
        ("falloff_start = 20.0", "falloff_start = 30.0", "lights[1]: falloff_start"),
        ("position = [2.0, 3.0, 1.0]", 'position = "up"', "lights[0]: position must be 3 finite numbers"),
        ("angle = 0.53", "angle = 190.0", "lights[2]: angle must be"),
        ("direction = [-0.3, -1.0, 0.2]", "direction = [0, 0, 0]", "lights[2]: directional light: direction"),
        ("irradiance_scale = 2.0", "irradiance_scale = -2.0", "lights[2]: irradiance_scale must be >= 0"),
        ("irradiance = [3.0, 2.8, 2.5]\n", "", "lights[2]: missing required key 'irradiance'"),
    ],
)
def test_light_mistakes_are_one_error_naming_the_light(scene_dir, old, new, message):
    assert old in LIGHTS
    _assert_one_error(scene_dir / "scene.toml", SCENE + LIGHTS.replace(old, new, 1), message)


def _key_lines(text):
    """(line index, key, value) of every `key = value`, including the keys of one-line inline tables."""
    import re

    found = []
    for i, line in enumerate(text.splitlines()):
        m = re.fullmatch(r"(\w+) = (.+)", line)
        if not m:
            continue
        key, value = m.groups()
        if value.startswith("{"):
            for inner in re.finditer(r"(\w+) = (\[[^\]]*\]|[^,}]+)", value[1:-1]):
                found.append((i, f"{key}.{inner.group(1)}", inner.group(2).strip()))
        else:
            found.append((i, key, value))
    return found


def _scene_texts():
    """The example scene with every optional key written out, and variants for the other environment sources."""
    full = (
        (SCENE + EXTRA_RENDER_KEYS)
        .replace("fov = 35\n", 'fov = 35\nup = [0.0, 1.0, 0.0]\nfov_axis = "y"\n')
        .replace(
            "rotation = 30.0\n",
            'rotation = 30.0\nmapping = "latlong"\nlookup = "bilinear"\npdf = "exact"\npdf_weights = "bilinear"\n',
        )
        .replace('file = "meshes/box.obj"\n', 'file = "meshes/box.obj"\nsmooth = true\n')
        .replace('type = "ground"\n', 'type = "ground"\nheight = 0.0\n')
        .replace("exponent = 200\n", 'exponent = 200\nestimator = "mixture"\n')
        + '[materials.metal]\ntype = "conductor"\nalpha = 0.2\neta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.2]\n'
        "specular_reflectance = 0.9\nfresnel = true\n"
        + '[[objects]]\ntype = "mesh"\nfile = "meshes/panels.ply"\nface_emission = "meshes/panels.npy"\n'
        + LIGHTS
    )
    sky = full.replace('[environment]\nfile = "sky.exr"\n', SKY)
    white = full.replace('[environment]\nfile = "sky.exr"\n', "[environment]\nconstant = [1.0, 0.5, 0.25]\n")
    return {"file-env": full, "sky-env": sky, "constant-env": white}


def _cases():
    cases = []
    for variant, text in _scene_texts().items():
        for i, key, value in _key_lines(text):
            if variant != "file-env" and not key.startswith(("sky", "constant")):
                continue  # the other variants differ only in the environment's source
            leaf = key.split(".")[-1]
            for wrong in WRONG_VALUES:
                if wrong == '"x"' and leaf in STRING_KEYS:
                    continue
                cases.append(pytest.param(variant, i, key, value, wrong, id=f"{variant}-{key}={wrong}"))
    return cases


@pytest.mark.parametrize(("variant", "line", "key", "value", "wrong"), _cases())
def test_every_key_of_the_wrong_type_is_one_error_naming_it(scene_dir, variant, line, key, value, wrong):
    """Any value of the wrong type or range is a SceneError naming the key (never a TypeError traceback), and a
    value that loads must also pass the render settings' validation."""
    from lightprobe.cli import _render_settings

    lines = _scene_texts()[variant].splitlines()
    leaf = key.split(".")[-1]
    if "." in key:
        lines[line] = lines[line].replace(f"{leaf} = {value}", f"{leaf} = {wrong}", 1)
    else:
        lines[line] = f"{key} = {wrong}"
    path = scene_dir / "scene.toml"
    path.write_text("\n".join(lines) + "\n")
    try:
        _, defaults = load_scene(path)
        _render_settings(defaults, {})
    except SceneError as exc:
        text = str(exc)
        assert "\n" not in text and "scene.toml" in text, text
        assert leaf in text or (leaf == "type" and "unknown" in text), text
        return
    # it loaded: only a value of the right type can (a negative angle, a string for a string key, ...)
    assert wrong in ("-1", "true", '"x"'), f"{key} = {wrong} was accepted"
    assert wrong != '"x"' or leaf in STRING_KEYS


PANEL_FACES = [[0, 1, 2], [0, 2, 3]]


def _panels_file(folder, colors=None):
    vertices = [[0, 2, 0], [1, 2, 0], [1, 2, 1], [0, 2, 1]]
    mesh = trimesh.Trimesh(vertices, PANEL_FACES, process=False, face_colors=colors)
    mesh.export(folder / "panels.ply")


def _mesh_scene(folder, extra):
    text = SCENE.split("[[objects]]")[0].replace('file = "sky.exr"', "constant = [0.1, 0.1, 0.1]")
    (folder / "m.toml").write_text(text + f'[[objects]]\ntype = "mesh"\nfile = "panels.ply"\n{extra}\n')
    return folder / "m.toml"


def test_a_mesh_takes_one_radiance_per_face_from_a_file_or_its_colours(tmp_path):
    """face_emission = "x.npy" ((F, 3) or (F,)) or "colors" (the file's face colours / 255), times emission_scale:
    one light per face with its own radiance."""
    _panels_file(tmp_path, colors=[[255, 0, 0, 255], [0, 51, 255, 255]])
    np.save(tmp_path / "rgb.npy", np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]))
    np.save(tmp_path / "grey.npy", np.array([2.0, 0.5]))
    cases = {
        'face_emission = "rgb.npy"\nemission_scale = 2.0': [[2.0, 4.0, 6.0], [8.0, 10.0, 12.0]],
        'face_emission = "grey.npy"': [[2.0, 2.0, 2.0], [0.5, 0.5, 0.5]],
        'face_emission = "colors"\nemission_scale = 10.0': [[10.0, 0.0, 0.0], [0.0, 2.0, 10.0]],
    }
    for extra, expected in cases.items():
        scene, _ = load_scene(_mesh_scene(tmp_path, extra))
        table = scene.light_table()  # the faces' rows, then the environment's
        np.testing.assert_allclose(table.radiance[:2], expected, err_msg=extra)
        assert table.kind.shape == (3,)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ('face_emission = "missing.npy"', "missing.npy: no such file"),
        ('face_emission = "three.npy"', "one row per face"),
        ('face_emission = "text.npy"', "text.npy: face_emission must be"),
        ('face_emission = "colors"', "has no face colours"),
        ('face_emission = "bad.npy"', "face_emission must give each face"),
        ('face_emission = "rgb.npy"\nemission = 1.0', "emission or face_emission, not both"),
        ('face_emission = "rgb.txt"', 'must be "colors" or a .npy file'),
        ('face_emission = "empty.npy"', r"empty\.npy: not a \.npy array \(the file is empty\)"),
        ('face_emission = "garbage.npy"', r"garbage\.npy: not a \.npy array \(10 bytes"),
        ('face_emission = "archive.npy"', r"archive\.npy: not a \.npy array"),
        ('face_emission = "cut.npy"', r"cut\.npy: not a readable \.npy array"),
    ],
)
def test_face_emission_mistakes_are_one_error_naming_the_file(tmp_path, extra, message):
    _panels_file(tmp_path)
    np.save(tmp_path / "rgb.npy", np.ones((2, 3)))
    np.save(tmp_path / "three.npy", np.ones((3, 3)))
    np.save(tmp_path / "text.npy", np.array(["a", "b"]))
    np.save(tmp_path / "bad.npy", np.array([[1.0, np.nan, 0.0], [1.0, 1.0, 1.0]]))
    # damaged files: numpy read these as an EOFError, a "pickled data" complaint, an archive and a short read
    (tmp_path / "empty.npy").write_bytes(b"")
    (tmp_path / "garbage.npy").write_bytes(b"\xab" * 10)
    np.savez(tmp_path / "archive.npz", a=np.ones((2, 3)))
    (tmp_path / "archive.npz").rename(tmp_path / "archive.npy")
    (tmp_path / "cut.npy").write_bytes((tmp_path / "rgb.npy").read_bytes()[:100])
    with pytest.raises(SceneError, match=message) as info:
        load_scene(_mesh_scene(tmp_path, extra))
    assert "\n" not in str(info.value) and ("m.toml" in str(info.value) or "panels" in str(info.value))
