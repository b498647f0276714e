"""The built-in demo scene: no files needed.

A procedural sky with a 0.5-degree sun (40,000 times brighter than the sky) lights a grey ground, a noisy red
plastic blob (a displaced icosphere, 20,480 triangles), a polished aluminium sphere, a rough gold sphere and a
small green diffuse sphere: every material and both kinds of geometry, and a light that neither BSDF sampling nor
environment sampling handles alone.
"""

from __future__ import annotations

import numpy as np

from .bsdfs import GGXConductor, Lambert, RoughPlastic
from .emitters.envmap import EnvironmentMap
from .emitters.procedural import sky_with_sun
from .geometry.camera import Camera
from .geometry.mesh import TriangleMesh
from .geometry.scene import Scene
from .geometry.shapes import Rectangle, Sphere

__all__ = ["blob_mesh", "demo_scene"]


def blob_mesh(subdivisions: int = 5) -> TriangleMesh:
    """A unit icosphere with smooth sinusoidal bumps (20 x 4^subdivisions triangles)."""
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = np.asarray(ico.vertices, dtype=np.float64)
    x, y, z = v.T
    bump = 0.10 * np.sin(3 * x + 1) * np.sin(4 * y) * np.sin(3 * z + 2) + 0.04 * np.sin(11 * x) * np.sin(13 * y + 1)
    return TriangleMesh.from_arrays(v * (1.0 + bump)[:, None], np.asarray(ico.faces), name="demo blob")


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
