"""Textures from a scene file: a Lambert material's base_color_texture on an OBJ quad whose UVs come from the file
(OBJ's v up the image, read in glTF's convention), rendered against albedo x texel x sky; refused inputs in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.errors import SceneError
from lightprobe.integrators import RenderSettings, render
from lightprobe.io.scene_file import load_scene
from lightprobe.textures.image_texture import SRGB_TABLE

OBJ = """v -1 0 1
v 1 0 1
v 1 0 -1
v -1 0 -1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
f 1/1 2/2 3/3
f 1/1 3/3 4/4
"""


def _write(tmp_path, material_extra: str, texels=None):
    import OpenImageIO as oiio

    (tmp_path / "quad.obj").write_text(OBJ)
    if texels is not None:
        out = oiio.ImageOutput.create(str(tmp_path / "albedo.png"))
        out.open(str(tmp_path / "albedo.png"), oiio.ImageSpec(2, 2, 3, oiio.UINT8))
        out.write_image(texels)
        out.close()
    fov = 2 * math.degrees(math.atan(0.5))  # the quad fills the view (tests/textures/test_textured_render.py)
    (tmp_path / "s.toml").write_text(
        f"[camera]\norigin = [0, 2, 0]\ntarget = [0, 0, 0]\nup = [0, 0, -1]\nfov = {fov}\nresolution = [16, 16]\n"
        "[environment]\nconstant = 0.5\n"
        f'[materials.tiles]\ntype = "lambert"\nalbedo = 0.8\n{material_extra}\n'
        '[[objects]]\ntype = "mesh"\nfile = "quad.obj"\nmaterial = "tiles"\nsmooth = false\n'
    )
    return tmp_path / "s.toml"


def test_a_scene_file_texture_on_an_obj_with_uvs(tmp_path):
    texels = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [128, 128, 128]]], np.uint8)
    path = _write(tmp_path, 'base_color_texture = "albedo.png"\ntexture_filter = "nearest"\ntexture_wrap = "clamp"',
                  texels)  # fmt: skip
    scene, _ = load_scene(path)
    image = render(scene, RenderSettings(spp=2, strategy="brdf")).image
    # quadrant (row, column) of the image shows texel (row, column): the OBJ's v = 1 is the image's top
    for r in range(2):
        for c in range(2):
            block = image[8 * r + 2 : 8 * r + 6, 8 * c + 2 : 8 * c + 6]
            np.testing.assert_allclose(block, np.broadcast_to(0.5 * 0.8 * SRGB_TABLE[texels[r, c]], block.shape),
                                       rtol=2e-7)  # fmt: skip


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ('base_color_texture = "none.png"', r"none\.png: no such file"),
        ('normal_texture = "albedo.png"\ntexture_wrap = "wrap"', "texture_wrap must be one of"),
        ('metallic_roughness_texture = "albedo.png"', "Lambert: takes no metallic_roughness texture"),
        ('alpha_mode = "blend"', "alpha_mode must be one of 'opaque', 'mask'"),
    ],
)
def test_scene_file_texture_errors_are_one_line(tmp_path, extra, message):
    path = _write(tmp_path, extra, np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(SceneError, match=message) as info:
        load_scene(path)
    assert "\n" not in str(info.value) and "tiles" in str(info.value)


def test_textures_on_a_material_that_takes_none(tmp_path):
    path = _write(tmp_path, 'base_color_texture = "albedo.png"', np.zeros((2, 2, 3), np.uint8))
    text = path.read_text().replace('type = "lambert"\nalbedo = 0.8', 'type = "conductor"\nmaterial = "Au"')
    path.write_text(text)
    with pytest.raises(SceneError, match="textures are taken by lambert and metallic_roughness materials, not"):
        load_scene(path)
