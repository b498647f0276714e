"""The built-in demo scene: no files needed.

A procedural sky with a 0.5-degree sun (40,000 times brighter than the sky) lights a grey ground, a noisy red
plastic blob (a displaced icosphere, 20,480 triangles), a polished aluminium sphere, a rough gold sphere and a
small green diffuse sphere: every material and both kinds of geometry, and a light that neither BSDF sampling nor
environment sampling handles alone.
"""

from __future__ import annotations

import math

import numpy as np

from .bsdfs import GGXConductor, Lambert, RoughPlastic
from .emitters.envmap import EnvironmentMap
from .emitters.procedural import sky_with_sun
from .geometry.camera import Camera
from .geometry.icosphere import icosphere
from .geometry.mesh import TriangleMesh
from .geometry.shapes import Rectangle, Sphere
from .scene import Scene

__all__ = ["DEMOS", "blob_mesh", "demo_scene", "many_lights_scene"]


def blob_mesh(subdivisions: int = 5) -> TriangleMesh:
    """A unit icosphere with smooth sinusoidal bumps (20 x 4^subdivisions triangles)."""
    v, faces = icosphere(subdivisions)
    x, y, z = v.T
    bump = 0.10 * np.sin(3 * x + 1) * np.sin(4 * y) * np.sin(3 * z + 2) + 0.04 * np.sin(11 * x) * np.sin(13 * y + 1)
    return TriangleMesh.from_arrays(v * (1.0 + bump)[:, None], faces, name="demo blob")


def demo_scene(resolution: tuple[int, int] = (640, 400)) -> Scene:
    env = EnvironmentMap.from_array(sky_with_sun(1024, 512), source="procedural sky with sun")
    camera = Camera([0.0, 1.7, 6.8], [0.0, 0.85, 0.0], fov=32.0, resolution=resolution)
    scene = Scene(camera, env, name="demo")
    scene.add(Rectangle.ground(size=1000.0), Lambert(0.5), name="ground")
    scene.add(
        blob_mesh(),
        RoughPlastic([0.6, 0.15, 0.1], 0.3),
        transform={"scale": 0.8, "translate": [0, 0.85, -0.3]},
        name="blob",
    )
    scene.add(Sphere([-1.75, 0.6, 0.7], 0.6), GGXConductor(0.05, material="Al"), name="aluminium sphere")
    scene.add(Sphere([1.7, 0.55, 0.9], 0.55), GGXConductor(0.3, material="Au"), name="gold sphere")
    scene.add(Sphere([0.35, 0.35, 1.6], 0.35), Lambert([0.2, 0.5, 0.25]), name="green sphere")
    return scene


def light_panels(n_lights: int, *, seed: int = 7, height: float = 2.4, extent: float = 6.0):
    """``n_lights`` small emitters facing down over a square of side ``extent`` at ``height``: half of them
    triangles, half of them quads (two triangles each, so ``n_lights`` counts triangles), with radiance spread
    log-uniformly over four decades and warm-to-cold colours.  Returns (vertices, faces, per-face radiance)."""
    rng = np.random.default_rng(seed)
    n_quads = n_lights // 4  # a quad is two triangle lights
    n_tris = n_lights - 2 * n_quads
    centres = np.column_stack(
        [
            rng.uniform(-extent / 2, extent / 2, n_quads + n_tris),
            height + rng.uniform(-0.3, 0.3, n_quads + n_tris),
            rng.uniform(-extent / 2, extent / 2, n_quads + n_tris),
        ]
    )
    size = 0.35 * extent / math.sqrt(n_quads + n_tris)
    angle = rng.uniform(0, 2 * math.pi, n_quads + n_tris)
    c, s = np.cos(angle), np.sin(angle)
    vertices, faces, radiance = [], [], []
    level = 10.0 ** rng.uniform(-1.0, 3.0, n_quads + n_tris) * (3.0 / math.sqrt(max(n_lights, 1)))
    hue = rng.uniform(0.0, 1.0, n_quads + n_tris)
    tint = np.column_stack([1.0 - 0.5 * hue, 0.75 + 0.0 * hue, 0.5 + 0.5 * hue])
    for i in range(n_quads + n_tris):
        ex = size * np.array([c[i], 0.0, s[i]])
        ez = size * np.array([-s[i], 0.0, c[i]])
        o = centres[i]
        base = len(vertices)
        if i < n_quads:  # winding so that the normal is -Y (facing the ground)
            vertices += [o - ex - ez, o + ex - ez, o + ex + ez, o - ex + ez]
            faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
            radiance += [level[i] * tint[i]] * 2
        else:
            vertices += [o - ex - ez, o + ex - ez, o + ez]
            faces += [[base, base + 1, base + 2]]
            radiance += [level[i] * tint[i]]
    v = np.array(vertices, dtype=np.float64)
    f = np.array(faces, dtype=np.int64)
    # winding: (v1 - v0) x (v2 - v0) = ex x ez ... make every face point down
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    flip = n[:, 1] > 0
    f[flip] = f[flip][:, [0, 2, 1]]
    return v, f, np.array(radiance, dtype=np.float64)


def many_lights_scene(n_lights: int = 4000, resolution: tuple[int, int] = (480, 320), *, view: str = "demo") -> Scene:
    """The lecture's many-light setting, no files needed: ``n_lights`` small emissive quads and triangles of
    powers spread over four decades, above a grey ground with a plastic blob, a rough gold sphere, a rough
    aluminium sphere and a diffuse green sphere; no environment (the lights alone).  ``view="demo"`` shows the
    lights from below; ``view="lit"`` looks down on the lit objects only (for error measurements that the pixels
    partly covered by a bright light would otherwise dominate)."""
    if view == "lit":
        camera = Camera([0.0, 2.0, 6.5], [0.0, 0.2, 0.0], fov=30.0, resolution=resolution)
    else:
        camera = Camera([0.0, 1.2, 7.0], [0.0, 1.0, 0.0], fov=45.0, resolution=resolution)
    scene = Scene(camera, None, name=f"many-lights ({n_lights})")
    scene.add(Rectangle.ground(size=40.0), Lambert(0.5), name="ground")
    scene.add(
        blob_mesh(4),
        RoughPlastic([0.6, 0.15, 0.1], 0.3),
        transform={"scale": 0.8, "translate": [0, 0.85, -0.3]},
        name="blob",
    )
    scene.add(Sphere([-1.75, 0.6, 0.7], 0.6), GGXConductor(0.2, material="Al"), name="aluminium sphere")
    scene.add(Sphere([1.7, 0.55, 0.9], 0.55), GGXConductor(0.3, material="Au"), name="gold sphere")
    scene.add(Sphere([0.35, 0.35, 1.6], 0.35), Lambert([0.2, 0.5, 0.25]), name="green sphere")
    v, f, radiance = light_panels(n_lights)
    scene.add(TriangleMesh.from_arrays(v, f, smooth=False, name="light panels"), emission=radiance, name="lights")
    return scene


DEMOS = {"default": demo_scene, "many-lights": many_lights_scene}
