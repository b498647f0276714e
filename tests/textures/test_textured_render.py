"""Textured materials in the render core, against closed forms and against themselves.

The scene: a 2 x 2 quad in the y = 0 plane facing +y, seen straight down by a camera whose view it exactly fills, so
that pixel (i, j) of an N x N image covers texture coordinates [i/N, (i+1)/N) x [j/N, (j+1)/N) (a plane parallel to
the image plane projects affinely; the camera's box filter keeps each sample in its pixel)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert, MetallicRoughness
from lightprobe.emitters.directional import DirectionalLight
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.errors import SceneError
from lightprobe.geometry import Camera, Rectangle, Sphere
from lightprobe.geometry.mesh import TriangleMesh
from lightprobe.integrators import RenderSettings, render
from lightprobe.scene import Scene
from lightprobe.textures import ImageTexture, MaterialTextures
from lightprobe.textures.image_texture import SRGB_TABLE

N = 32
QUAD = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]])
FACES = np.array([[0, 2, 1], [0, 3, 2]])  # facing +y
UVS = (QUAD[:, [0, 2]] + 1.0) / 2.0  # u along +x, v along +z (down the image: the camera's up is -z)


def quad(**options) -> TriangleMesh:
    return TriangleMesh.from_arrays(QUAD, FACES, np.tile([0.0, 1.0, 0.0], (4, 1)), uvs=UVS, **options)


def camera() -> Camera:
    height = 2.0  # tan(fov / 2) = 1 / height: the quad fills the view
    return Camera([0.0, height, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0], fov=2 * math.degrees(math.atan(0.5)),
                  resolution=(N, N))  # fmt: skip


def sky(radiance=0.75) -> EnvironmentMap:
    return EnvironmentMap.from_array(np.full((8, 16, 3), radiance))


def test_textured_lambert_plane_under_a_constant_sky_is_albedo_times_texel_times_sky():
    """Under a constant sky L every point of an unoccluded Lambert plane reflects albedo x texel x L; with BSDF
    sampling each sample is that exactly, so pixels inside a texel equal the closed form to float32 rounding, and
    under MIS they agree with it within their noise (pooled z)."""
    rng = np.random.default_rng(7)
    codes = rng.integers(0, 256, size=(N // 4, N // 4, 3), dtype=np.uint8)  # 4 x 4 pixels per texel
    albedo = np.array([0.9, 0.6, 0.8])
    texture = ImageTexture(codes, filter="nearest", wrap="clamp")
    scene = Scene(camera(), sky(0.75))
    scene.add(quad(), Lambert(albedo, textures=MaterialTextures(base_color=texture)))
    expected = 0.75 * albedo * SRGB_TABLE[codes]  # (N/4, N/4, 3)
    expected = np.repeat(np.repeat(expected, 4, axis=0), 4, axis=1)
    inner = np.zeros((N, N), bool)  # pixels away from a texel's edge (a sample's float rounding cannot cross it)
    inner[np.ix_(np.arange(N) % 4 % 3 != 0, np.arange(N) % 4 % 3 != 0)] = True
    exact = render(scene, RenderSettings(spp=4, strategy="brdf"))
    np.testing.assert_allclose(exact.image[inner], expected[inner], rtol=2e-7, atol=0)
    mis = render(scene, RenderSettings(spp=64, seed=3))
    z = (mis.image[inner] - expected[inner]) / np.sqrt(mis.variance[inner] + 1e-30)
    assert abs(z.mean() * math.sqrt(z.size)) < 4.0 and np.mean(np.abs(z) > 4) < 0.01


def test_white_textures_and_a_flat_normal_map_leave_the_image_bit_for_bit():
    rng = np.random.default_rng(8)
    env = EnvironmentMap.from_array(rng.random((16, 32, 3)) * 2.0)
    material = dict(base_color=[0.8, 0.5, 0.3], metallic=0.3, roughness=0.4)
    white = ImageTexture(np.full((3, 5, 4), 255, np.uint8))
    flat = ImageTexture(np.tile(np.float32([0.5, 0.5, 1.0]), (4, 4, 1)))
    cam = Camera([0.6, 1.5, 1.2], [0.0, 0.0, 0.0], fov=60, resolution=(N, N))
    images = []
    for textures in (None, MaterialTextures(base_color=white, metallic_roughness=white, normal=flat)):
        scene = Scene(cam, env)
        scene.add(quad(), MetallicRoughness(**material, textures=textures), two_sided=True)
        scene.add(Sphere([0.3, 0.3, 0.0], 0.3), MetallicRoughness(**material))
        images.append(render(scene, RenderSettings(spp=8, seed=2)).image)
    assert images[0].mean() > 0.05
    np.testing.assert_array_equal(images[0], images[1])


def test_a_constant_texture_agrees_with_the_same_factors_written_without_textures():
    """Base colour 0.5 x an sRGB texel 188 and roughness 0.8 x a linear texel 128 against factors that are the
    products: the two images agree per 4 x 4 block within their noise."""
    from lightprobe.analysis.metrics import block_z_test

    env = EnvironmentMap.from_array(np.random.default_rng(9).random((16, 32, 3)) * 3.0)
    base = ImageTexture(np.full((2, 2, 3), 188, np.uint8))
    mr = ImageTexture(np.dstack([np.zeros((2, 2)), np.full((2, 2), 128), np.full((2, 2), 255)]).astype(np.uint8))
    cam = Camera([0.6, 1.5, 1.2], [0.0, 0.0, 0.0], fov=60, resolution=(N, N))
    a, b = Scene(cam, env), Scene(cam, env)
    a.add(quad(), MetallicRoughness(0.5, 0.4, 0.8, textures=MaterialTextures(base_color=base, metallic_roughness=mr)))
    b.add(quad(), MetallicRoughness(0.5 * SRGB_TABLE[188], 0.4, 0.8 * 128 / 255))
    ra, rb = render(a, RenderSettings(spp=64, seed=1)), render(b, RenderSettings(spp=64, seed=2))
    verdict = block_z_test(ra.image, ra.variance, rb.image, rb.variance, block=4)
    assert abs(verdict["pooled_z"]) < 4.0 and verdict["outliers"] <= 0.05, verdict
    assert not np.array_equal(ra.image, rb.image)  # two seeds: a real comparison


@pytest.mark.parametrize("texel", [(0.8, 0.3, 0.9), (0.35, 0.7, 0.9), (0.5, 0.5, 1.0)])
def test_normal_map_tilts_the_shading_normal_along_the_tangent_and_toward_the_top_of_the_image(texel):
    """A Lambert plane under a delta sun reflects albedo / pi x E x cos(n', sun) with n' the mapped normal
    normalize((2c - 1)(s, s, 1)) in (tangent +x, bitangent toward the image's top -z, normal +y): every pixel, to
    float rounding (a delta light's estimate has no variance)."""
    scale = 1.5
    sun = np.array([1.0, 1.0, -0.3]) / np.linalg.norm([1.0, 1.0, -0.3])  # toward the sun
    scene = Scene(camera(), None)
    normal = ImageTexture(np.tile(np.float32(texel), (2, 2, 1)))
    scene.add(quad(), Lambert(0.7, textures=MaterialTextures(normal=normal, normal_scale=scale)))
    scene.add_light(DirectionalLight(-sun, 2.0))
    x, y, z = (2 * np.array(texel) - 1) * [scale, scale, 1.0]
    n = x * np.array([1.0, 0.0, 0.0]) + y * np.array([0.0, 0.0, -1.0]) + z * np.array([0.0, 1.0, 0.0])
    n /= np.linalg.norm(n)
    expected = 0.7 / math.pi * 2.0 * max(float(n @ sun), 0.0)
    image = render(scene, RenderSettings(spp=2)).image
    np.testing.assert_allclose(image, expected, rtol=1e-6)


def test_textures_need_a_mesh_with_texture_coordinates_and_a_material_that_takes_them():
    textures = MaterialTextures(base_color=ImageTexture(np.ones((2, 2))))
    scene = Scene(camera(), sky())
    with pytest.raises(SceneError, match="need a triangle mesh with texture coordinates, not a sphere"):
        scene.add(Sphere([0, 0, 0], 1), Lambert(0.5, textures=textures))
    with pytest.raises(SceneError, match="not a rectangle"):
        scene.add(Rectangle.ground(size=4), Lambert(0.5, textures=textures))
    with pytest.raises(SceneError, match="the mesh has no texture coordinates"):
        scene.add(TriangleMesh.from_arrays(QUAD, FACES), Lambert(0.5, textures=textures))
    mr = MaterialTextures(metallic_roughness=ImageTexture(np.ones((2, 2))))
    with pytest.raises(Exception, match="Lambert: takes no metallic_roughness texture"):
        Lambert(0.5, textures=mr)


def test_texture_memory_is_counted_once_per_texture():
    shared = ImageTexture(np.zeros((64, 32, 3), np.uint8))
    scene = Scene(camera(), sky())
    scene.add(quad(), Lambert(0.5, textures=MaterialTextures(base_color=shared)))
    scene.add(quad(), MetallicRoughness(textures=MaterialTextures(base_color=shared, normal=ImageTexture(
        np.zeros((4, 4, 3), np.float32)))))  # fmt: skip
    assert scene.texture_bytes == 64 * 32 * 4 + 4 * 4 * 16
    assert "materials (0.0 MiB of textures)" in scene.summary()
    untextured = Scene(camera(), sky())
    untextured.add(quad(), Lambert(0.5))
    assert "textures" not in untextured.summary()
