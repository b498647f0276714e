"""Object-id pass: which scene object each pixel's centre sees, for metrics restricted to one object."""

from __future__ import annotations

import numpy as np

from ..geometry.intersect import MESH, MISS, RECT, SPHERE
from ..geometry.mesh import TriangleMesh
from ..geometry.raytracer import RayTracer
from ..geometry.shapes import Rectangle, Sphere
from ..scene import Scene

__all__ = ["BACKGROUND", "object_id_pass"]

BACKGROUND = -1


def object_id_pass(scene: Scene) -> tuple[np.ndarray, list[str]]:
    """(ids (H, W) int32, names): ``ids`` is the index in ``scene.objects`` of the object hit by the ray through
    each pixel's centre, :data:`BACKGROUND` (-1) where it sees the environment; ``names`` the objects' names."""
    width, height = scene.camera.resolution
    pixels = np.arange(width * height)
    origins, dirs = scene.camera.rays(pixels, np.full((pixels.size, 2), 0.5))
    tracer = RayTracer(scene.compile())
    try:
        _, kind, index, *_ = tracer.intersect(origins, dirs)
    finally:
        tracer.close()
    # the compiled scene numbers meshes, spheres and rectangles separately, each in the order they were added
    by_kind = {
        MESH: [i for i, o in enumerate(scene.objects) if isinstance(o.shape, TriangleMesh)],
        SPHERE: [i for i, o in enumerate(scene.objects) if isinstance(o.shape, Sphere)],
        RECT: [i for i, o in enumerate(scene.objects) if isinstance(o.shape, Rectangle)],
    }
    ids = np.full(pixels.size, BACKGROUND, dtype=np.int32)
    for k, objects in by_kind.items():
        hit = kind == k
        if objects and hit.any():
            ids[hit] = np.asarray(objects, dtype=np.int32)[index[hit]]
    ids[kind == MISS] = BACKGROUND
    return ids.reshape(height, width), [o.name for o in scene.objects]
