"""A scene: camera, environment light, materials and objects (meshes, spheres, rectangles).

Build one from Python::

    scene = Scene(Camera(...), EnvironmentMap.load("sky.exr"))
    scene.add_material("red", RoughPlastic([0.6, 0.15, 0.1], 0.3))
    scene.add(TriangleMesh.load("bunny.obj"), "red", transform={"scale": 5, "translate": [0, 1, 0]})
    scene.add(Sphere([1, 0.5, 0], 0.5), GGXConductor(0.05, material="Al"))
    scene.add(Rectangle.ground(size=100), Lambert(0.5))

or from a TOML file with :func:`lightprobe.io.scene_file.load_scene` (``Scene.load``).  :meth:`Scene.compile`
flattens everything into the plain arrays the Numba kernels read (:class:`SceneArrays`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..bsdfs.base import BSDF, PARAM_SIZE
from ..emitters.envmap import EnvironmentMap
from ..errors import SceneError
from .camera import Camera
from .mesh import TriangleMesh
from .shapes import Rectangle, Sphere
from .transform import make_transform

__all__ = ["Scene", "SceneArrays", "SceneObject"]

Shape = TriangleMesh | Sphere | Rectangle


@dataclass(frozen=True)
class SceneObject:
    shape: Shape
    material: str
    two_sided: bool
    name: str


class SceneArrays(NamedTuple):
    """Everything the kernels need, as arrays (world space)."""

    mesh_vertices: np.ndarray  # (V, 3) float64
    mesh_normals: np.ndarray  # (V, 3) float64, zeros for flat meshes
    mesh_faces: np.ndarray  # (F, 3) int64, indices into mesh_vertices
    mesh_face_start: np.ndarray  # (M + 1,) int64: mesh g owns faces [start[g], start[g+1])
    mesh_smooth: np.ndarray  # (M,) int64, 1 = interpolate vertex normals
    mesh_material: np.ndarray  # (M,) int64
    mesh_two_sided: np.ndarray  # (M,) int64
    mesh_bounds: np.ndarray  # (M, 2, 3) float64
    spheres: np.ndarray  # (S, 4) float64: centre, radius
    sphere_material: np.ndarray
    sphere_two_sided: np.ndarray
    rects: np.ndarray  # (R, 12) float64: origin, edge_u, edge_v, unit normal
    rect_material: np.ndarray
    rect_two_sided: np.ndarray
    material_kind: np.ndarray  # (K,) int64
    material_params: np.ndarray  # (K, PARAM_SIZE) float64


class Scene:
    """Camera + environment + objects.  See the module docstring."""

    def __init__(self, camera: Camera, environment: EnvironmentMap, *, name: str = "scene"):
        if not isinstance(camera, Camera):
            raise SceneError("camera must be a lightprobe Camera")
        if not isinstance(environment, EnvironmentMap):
            raise SceneError("environment must be a lightprobe EnvironmentMap")
        self.camera = camera
        self.environment = environment
        self.name = name
        self.materials: dict[str, BSDF] = {}
        self.objects: list[SceneObject] = []

    def add_material(self, name: str, bsdf: BSDF) -> str:
        if not isinstance(bsdf, BSDF):
            raise SceneError(f"material {name!r} must be a BSDF, got {type(bsdf).__name__}")
        self.materials[name] = bsdf
        return name

    def add(
        self, shape: Shape, material: str | BSDF, *, transform=None, two_sided: bool = False, name: str | None = None
    ) -> SceneObject:
        """Add a shape with a material (a name registered with :meth:`add_material`, or a BSDF)."""
        label = name or f"object {len(self.objects)}"
        if isinstance(material, BSDF):
            material = self.add_material(f"{label} material", material)
        if material not in self.materials:
            raise SceneError(f"{label}: unknown material {material!r}; known: {', '.join(self.materials) or 'none'}")
        if transform is not None:
            matrix = transform if isinstance(transform, np.ndarray) else make_transform(transform)
            if isinstance(shape, TriangleMesh):
                shape = shape.transformed(matrix)
            else:
                raise SceneError(f"{label}: transforms apply to meshes; place spheres and rectangles directly")
        if not isinstance(shape, TriangleMesh | Sphere | Rectangle):
            raise SceneError(f"{label}: unsupported shape {type(shape).__name__}")
        obj = SceneObject(shape, material, bool(two_sided), label)
        self.objects.append(obj)
        return obj

    @classmethod
    def load(cls, path: str | os.PathLike) -> Scene:
        """Read a TOML scene file (see :mod:`lightprobe.io.scene_file`)."""
        from ..io.scene_file import load_scene

        return load_scene(path)[0]

    @property
    def triangle_count(self) -> int:
        return sum(o.shape.triangle_count for o in self.objects if isinstance(o.shape, TriangleMesh))

    def bounds(self) -> np.ndarray:
        boxes = [o.shape.bounds for o in self.objects]
        if not boxes:
            return np.zeros((2, 3))
        b = np.stack(boxes)
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    def compile(self) -> SceneArrays:
        names = list(self.materials)
        index = {n: i for i, n in enumerate(names)}
        kinds = np.array([self.materials[n].kind for n in names], dtype=np.int64)
        params = np.stack([self.materials[n].params for n in names]) if names else np.zeros((0, PARAM_SIZE))
        meshes = [o for o in self.objects if isinstance(o.shape, TriangleMesh)]
        spheres = [o for o in self.objects if isinstance(o.shape, Sphere)]
        rects = [o for o in self.objects if isinstance(o.shape, Rectangle)]

        vertices, normals, faces, starts, smooth, bounds = [], [], [], [0], [], []
        base = 0
        for o in meshes:
            m: TriangleMesh = o.shape
            vertices.append(m.vertices)
            normals.append(m.normals if m.normals is not None else np.zeros_like(m.vertices))
            faces.append(m.faces + base)
            base += m.vertices.shape[0]
            starts.append(starts[-1] + m.faces.shape[0])
            smooth.append(1 if m.normals is not None else 0)
            bounds.append(m.bounds)

        def ints(values):
            return np.asarray(values, dtype=np.int64).reshape(-1)

        return SceneArrays(
            np.ascontiguousarray(np.concatenate(vertices)) if vertices else np.zeros((0, 3)),
            np.ascontiguousarray(np.concatenate(normals)) if normals else np.zeros((0, 3)),
            np.ascontiguousarray(np.concatenate(faces)) if faces else np.zeros((0, 3), np.int64),
            ints(starts),
            ints(smooth),
            ints([index[o.material] for o in meshes]),
            ints([o.two_sided for o in meshes]),
            np.stack(bounds) if bounds else np.zeros((0, 2, 3)),
            np.array([[*o.shape.center, o.shape.radius] for o in spheres]).reshape(-1, 4),
            ints([index[o.material] for o in spheres]),
            ints([o.two_sided for o in spheres]),
            np.array([[*o.shape.origin, *o.shape.edge_u, *o.shape.edge_v, *o.shape.normal] for o in rects]).reshape(
                -1, 12
            ),
            ints([index[o.material] for o in rects]),
            ints([o.two_sided for o in rects]),
            kinds,
            np.ascontiguousarray(params),
        )

    def summary(self) -> str:
        w, h = self.camera.resolution
        return (
            f"{self.name}: {len(self.objects)} objects ({self.triangle_count} triangles), "
            f"{len(self.materials)} materials, {w}x{h}, light {self.environment.source}"
        )
