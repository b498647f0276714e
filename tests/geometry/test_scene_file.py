"""The TOML scene format: a full example loads; every mistake is one clear error naming file and place."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lightprobe.errors import SceneError
from lightprobe.geometry.scene import Scene
from lightprobe.io.images import write_image
from lightprobe.io.scene_file import load_scene

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
    assert isinstance(Scene.load(scene_dir / "scene.toml"), Scene)


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
        ("scale = 2.0", 'scale = "big"', "scale must be a number"),
        ("[camera]", "[camera\n", "not valid TOML"),
    ],
)
def test_errors_name_file_and_place(scene_dir, old, new, message):
    path = scene_dir / "scene.toml"
    assert old in SCENE
    path.write_text(SCENE.replace(old, new, 1))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    text = str(info.value)
    assert message in text and "scene.toml" in text, text
    assert "\n" not in text


def test_missing_file(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_scene(tmp_path / "nope.toml")
