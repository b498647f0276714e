"""Alpha cut-outs inside Embree: camera rays see through the holes to the sky, shadow rays pass through them (one at
a time and in packets), the coverage is alpha_factor x the texture's alpha against the cutoff, and an emitter is never
cut.  The scene's geometry is that of tests/textures/test_textured_render.py: a quad that exactly fills the view of a
camera straight above it, pixel (i, j) covering texture coordinates [i/N, (i+1)/N) x [j/N, (j+1)/N)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.punctual import PointLight
from lightprobe.geometry import Camera
from lightprobe.geometry.mesh import TriangleMesh
from lightprobe.geometry.raytracer import RayTracer
from lightprobe.integrators import RenderSettings, render
from lightprobe.scene import Scene
from lightprobe.textures import ImageTexture, MaterialTextures
from lightprobe.textures.image_texture import SRGB_TABLE

N = 32
QUAD = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]])
FACES = np.array([[0, 2, 1], [0, 3, 2]])
UVS = (QUAD[:, [0, 2]] + 1.0) / 2.0
UP = np.tile([0.0, 1.0, 0.0], (4, 1))
CHECKER = (np.indices((N // 4, N // 4)).sum(axis=0) % 2).astype(bool)  # True: opaque texel
INNER = np.zeros((N, N), bool)  # pixels away from a texel's edge
INNER[np.ix_(np.arange(N) % 4 % 3 != 0, np.arange(N) % 4 % 3 != 0)] = True
OPAQUE_PIXELS = np.repeat(np.repeat(CHECKER, 4, axis=0), 4, axis=1)


def camera() -> Camera:
    return Camera([0.0, 2.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0], fov=2 * math.degrees(math.atan(0.5)),
                  resolution=(N, N))  # fmt: skip


def mask_texture(alpha_opaque=255, alpha_hole=0) -> ImageTexture:
    alpha = np.where(CHECKER, alpha_opaque, alpha_hole).astype(np.uint8)
    return ImageTexture(np.dstack([np.full((N // 4, N // 4, 3), 200, np.uint8), alpha]), filter="nearest",
                        wrap="clamp")  # fmt: skip


def masked(**options) -> Lambert:
    return Lambert(0.8, textures=MaterialTextures(base_color=mask_texture(), alpha_mode="mask", **options))


def test_camera_rays_see_the_sky_through_the_holes_and_the_material_elsewhere():
    scene = Scene(camera(), EnvironmentMap.from_array(np.full((8, 16, 3), 0.25)))
    scene.add(TriangleMesh.from_arrays(QUAD, FACES, UP, uvs=UVS), masked(), two_sided=True)
    image = render(scene, RenderSettings(spp=4, strategy="brdf")).image[..., 0]
    opaque = INNER & OPAQUE_PIXELS
    hole = INNER & ~OPAQUE_PIXELS
    np.testing.assert_allclose(image[opaque], 0.25 * 0.8 * SRGB_TABLE[200], rtol=2e-7)
    np.testing.assert_allclose(image[hole], 0.25, rtol=2e-7)


@pytest.mark.parametrize("packets", [True, False])
def test_shadow_rays_pass_through_the_holes(monkeypatch, packets):
    """A point light at the camera: a ground point seen through a hole sends its shadow ray back along the camera
    ray, through the same hole, so it is lit exactly as with no quad at all; under an opaque texel the camera sees
    the quad.  Both shadow-ray paths (8-ray packets and single rays) go through the filter."""
    from lightprobe.geometry import embree

    monkeypatch.setattr(embree, "_native_packets", [packets and embree.packets_native()])
    images = []
    for with_quad in (False, True):
        scene = Scene(camera(), None)
        scene.add(TriangleMesh.from_arrays(QUAD * 3 - [0.0, 1.0, 0.0], FACES, UP), Lambert(0.5))
        if with_quad:
            scene.add(TriangleMesh.from_arrays(QUAD, FACES, UP, uvs=UVS), masked(), two_sided=True)
        scene.add_light(PointLight([0.0, 2.0, 0.0], 5.0))
        images.append(render(scene, RenderSettings(spp=4)).image[..., 0])
    ground, with_quad = images
    hole = INNER & ~OPAQUE_PIXELS
    assert ground[hole].min() > 0.05
    np.testing.assert_allclose(with_quad[hole], ground[hole], rtol=1e-6)
    assert np.all(np.abs(with_quad[INNER & OPAQUE_PIXELS] - ground[INNER & OPAQUE_PIXELS]) > 1e-3)


def test_rays_are_filtered_by_the_factor_times_the_texture_alpha_against_the_cutoff():
    """Texture alpha 0.6 on the 'opaque' texels, 0.2 in the holes: with factor 1 and cutoff 0.5 the checker stays;
    factor 0.5 (coverage 0.3 and 0.1) opens every texel; cutoff 0.15 closes every one."""
    origins = np.column_stack([np.linspace(-0.9, 0.9, 64), np.full(64, 1.0), np.linspace(0.9, -0.8, 64)])
    directions = np.tile([0.0, -1.0, 0.0], (64, 1))
    uv = (origins[:, [0, 2]] + 1.0) / 2.0
    expected_opaque = CHECKER[(uv[:, 1] * N // 4).astype(int), (uv[:, 0] * N // 4).astype(int)]
    texture = mask_texture(alpha_opaque=153, alpha_hole=51)
    for factor, cutoff, blocked in ((1.0, 0.5, expected_opaque), (0.5, 0.5, np.zeros(64, bool)),
                                    (1.0, 0.15, np.ones(64, bool))):  # fmt: skip
        scene = Scene(camera(), None)
        material = Lambert(0.8, textures=MaterialTextures(base_color=texture, alpha_mode="mask", alpha_cutoff=cutoff,
                                                          alpha_factor=factor))  # fmt: skip
        scene.add(TriangleMesh.from_arrays(QUAD, FACES, UP, uvs=UVS), material)
        tracer = RayTracer(scene.compile())
        try:
            hits = tracer.intersect(origins, directions)
            occluded = tracer.occluded(origins, directions)
        finally:
            tracer.close()
        t = hits[0] if isinstance(hits, tuple) else hits.t
        np.testing.assert_array_equal(np.isfinite(t), blocked)
        np.testing.assert_array_equal(occluded, blocked)


def test_an_emitter_is_never_cut_out():
    scene = Scene(camera(), None)
    with pytest.warns(UserWarning, match="an emitter is never cut out"):
        scene.add(TriangleMesh.from_arrays(QUAD, FACES, UP, uvs=UVS), masked(), emission=2.0)
    image = render(scene, RenderSettings(spp=2)).image[..., 0]
    np.testing.assert_allclose(image[INNER], 2.0, rtol=1e-6)


def test_a_mask_without_a_texture_needs_no_uvs_and_cuts_by_its_factor():
    """glTF allows alphaMode MASK with baseColorFactor's alpha alone: 0.3 against the cutoff 0.5 removes the whole
    mesh (which has no texture coordinates), 0.7 keeps it."""
    origins = np.array([[0.2, 1.0, -0.3], [-0.5, 1.0, 0.6]])
    directions = np.tile([0.0, -1.0, 0.0], (2, 1))
    for factor, hit in ((0.3, False), (0.7, True)):
        scene = Scene(camera(), None)
        textures = MaterialTextures(alpha_mode="mask", alpha_factor=factor)
        scene.add(TriangleMesh.from_arrays(QUAD, FACES, UP), Lambert(0.5, textures=textures))
        tracer = RayTracer(scene.compile())
        try:
            np.testing.assert_array_equal(tracer.occluded(origins, directions), [hit, hit])
        finally:
            tracer.close()
