"""A scene: camera, environment light, materials, objects (meshes, spheres, rectangles) and point, spot and
directional lights.

Build one from Python::

    scene = Scene(Camera(...), EnvironmentMap.load("sky.exr"))
    scene.add_material("red", RoughPlastic([0.6, 0.15, 0.1], 0.3))
    scene.add(TriangleMesh.load("bunny.obj"), "red", transform={"scale": 5, "translate": [0, 1, 0]})
    scene.add(Sphere([1, 0.5, 0], 0.5), GGXConductor(0.05, material="Al"))
    scene.add(Rectangle.ground(size=100), Lambert(0.5))
    scene.add_light(SpotLight([0, 4, 2], target=[0, 0, 0], intensity=50, cone_angle=25))

or from a TOML file with :func:`lightprobe.io.scene_file.load_scene`.  :meth:`Scene.compile`
flattens everything into the plain arrays the Numba kernels read (:class:`SceneArrays`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bsdfs.base import BSDF, PARAM_SIZE, rgb_param
from .emitters.envmap import EnvironmentMap
from .errors import LightprobeError, SceneError, numeric_array, warn_once
from .geometry.camera import Camera
from .geometry.intersect import rectangle_rows_of
from .geometry.mesh import TriangleMesh
from .geometry.scene_arrays import SceneArrays
from .geometry.shape_bvh import build_shape_tree
from .geometry.shapes import Rectangle, Sphere
from .geometry.transform import make_transform

__all__ = ["Scene", "SceneObject"]

Shape = TriangleMesh | Sphere | Rectangle


@dataclass(frozen=True)
class SceneObject:
    shape: Shape
    material: str
    two_sided: bool
    name: str
    emission: np.ndarray | None = None  # RGB radiance emitted (uniformly, on the front or both sides), or None


class Scene:
    """Camera + environment + objects.  See the module docstring."""

    def __init__(self, camera: Camera, environment: EnvironmentMap | None = None, *, name: str = "scene"):
        if not isinstance(camera, Camera):
            raise SceneError("camera must be a lightprobe Camera")
        if environment is not None and not isinstance(environment, EnvironmentMap):
            raise SceneError("environment must be a lightprobe EnvironmentMap (or None: area lights only)")
        self.camera = camera
        self.environment = environment
        self.name = name
        self.materials: dict[str, BSDF] = {}
        self.objects: list[SceneObject] = []
        # point, spot and directional lights (emitters/punctual.py, directional.py): in the light table after the
        # emitting objects' rows, the directional ones with the infinite lights
        self.lights: list = []
        #: cameras of included glTF files: name -> the asset that has it (``io/gltf.py``; ``render --camera``)
        self.cameras: dict = {}

    def add_material(self, name: str, bsdf: BSDF) -> str:
        if not isinstance(bsdf, BSDF):
            raise SceneError(f"material {name!r} must be a BSDF, got {type(bsdf).__name__}")
        self.materials[name] = bsdf
        return name

    def add(
        self,
        shape: Shape,
        material: str | BSDF | None = None,
        *,
        transform=None,
        two_sided: bool = False,
        name: str | None = None,
        emission=None,
    ) -> SceneObject:
        """Add a shape with a material (a name registered with :meth:`add_material`, or a BSDF).

        ``emission`` (a number or RGB radiance) makes the object an area light: uniform radiance leaving its front
        side (both sides if ``two_sided``); an emitter needs no material (it then reflects nothing).  Every
        triangle of an emissive mesh is a light of its own.
        """
        label = name or f"object {len(self.objects)}"
        if emission is not None:
            emission = _emission(emission, shape, label)
        if material is None:
            if emission is None:
                raise SceneError(f"{label}: needs a material (or an emission)")
            from .bsdfs import Lambert

            if "black" not in self.materials:
                self.add_material("black", Lambert(0.0))
            material = "black"
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
        if self.materials[material].textures is not None:
            if not isinstance(shape, TriangleMesh):
                raise SceneError(f"{label}: material {material!r} has textures, which need a triangle mesh with "
                                 f"texture coordinates, not a {type(shape).__name__.lower()}")  # fmt: skip
            if shape.uvs is None and self.materials[material].textures.used():
                raise SceneError(f"{label}: material {material!r} has textures but the mesh has no texture "
                                 "coordinates (UVs)")  # fmt: skip
            if emission is not None and self.materials[material].textures.masked:
                warn_once(f"{label}: an emitter is never cut out; material {material!r}'s alpha mask is ignored here")
        obj = SceneObject(shape, material, bool(two_sided), label, emission)
        self.objects.append(obj)
        return obj

    def add_light(self, light):
        """Add a :class:`~lightprobe.emitters.punctual.PointLight`, :class:`~lightprobe.emitters.punctual.SpotLight`,
        :class:`~lightprobe.emitters.directional.DirectionalLight` or :class:`~lightprobe.emitters.sun.SunLight` (an
        emitter without a surface)."""
        from .emitters.directional import DirectionalLight
        from .emitters.punctual import PointLight
        from .emitters.sun import SunLight

        if not isinstance(light, PointLight | DirectionalLight | SunLight):
            raise SceneError(
                f"add_light takes a PointLight, SpotLight, DirectionalLight or SunLight, got {type(light).__name__}"
            )
        self.lights.append(light)
        return light

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

        textures = _TextureRows([self.materials[n] for n in names])
        vertices, normals, faces, starts, smooth, bounds, proxies = [], [], [], [0], [], [], []
        uvs, tangents = [], []
        base = 0
        for o in meshes:
            m: TriangleMesh = o.shape
            uvs.append(m.uvs if m.uvs is not None else np.zeros((m.vertices.shape[0], 2)))
            tangents.append(textures.tangents(m, self.materials[o.material]))
            vertices.append(m.vertices)
            normals.append(m.normals if m.normals is not None else np.zeros_like(m.vertices))
            faces.append(m.faces + base)
            base += m.vertices.shape[0]
            starts.append(starts[-1] + m.faces.shape[0])
            smooth.append(1 if m.normals is not None else 0)
            bounds.append(m.bounds)
            proxies.append(textures.proxy_spheres(m, self.materials[o.material]))

        def ints(values):
            return np.asarray(values, dtype=np.int64).reshape(-1)

        # rows of the light table, in the order of light_table(): spheres, rectangles, then mesh faces
        row = 0
        sphere_light, rect_light, mesh_light = [], [], []
        for group, out in ((spheres, sphere_light), (rects, rect_light), (meshes, mesh_light)):
            for o in group:
                if o.emission is None:
                    out.append(-1)
                    continue
                out.append(row)
                row += _light_rows(o)

        sphere_rows = np.array([[*o.shape.center, o.shape.radius] for o in spheres]).reshape(-1, 4)
        rect_rows = rectangle_rows_of([o.shape for o in rects])
        return SceneArrays(
            np.ascontiguousarray(np.concatenate(vertices)) if vertices else np.zeros((0, 3)),
            np.ascontiguousarray(np.concatenate(normals)) if normals else np.zeros((0, 3)),
            np.ascontiguousarray(np.concatenate(faces)) if faces else np.zeros((0, 3), np.int64),
            ints(starts),
            ints(smooth),
            ints([index[o.material] for o in meshes]),
            ints([o.two_sided for o in meshes]),
            np.stack(bounds) if bounds else np.zeros((0, 2, 3)),
            np.stack(proxies) if proxies else np.zeros((0, 5)),
            sphere_rows,
            ints([index[o.material] for o in spheres]),
            ints([o.two_sided for o in spheres]),
            rect_rows,
            ints([index[o.material] for o in rects]),
            ints([o.two_sided for o in rects]),
            ints(sphere_light),
            ints(rect_light),
            ints(mesh_light),
            kinds,
            np.ascontiguousarray(params),
            textures.textured,
            textures.uses,
            textures.normal_scale,
            textures.alpha,
            np.ascontiguousarray(np.concatenate(uvs)) if uvs else np.zeros((0, 2)),
            np.ascontiguousarray(np.concatenate(tangents)) if tangents else np.zeros((0, 4)),
            textures.packed.table,
            textures.packed.bytes,
            textures.packed.floats,
            *build_shape_tree(sphere_rows, rect_rows),
        )

    @property
    def texture_bytes(self) -> int:
        """Bytes the render kernels hold for the scene's textures (each texture once)."""
        seen = {}
        for material in self.materials.values():
            if material.textures is not None:
                seen.update({id(t): t.nbytes for t in material.textures.used().values()})
        return sum(seen.values())

    @property
    def emitters(self) -> list[SceneObject]:
        return [o for o in self.objects if o.emission is not None]

    @property
    def bounded_light_count(self) -> int:
        """The lights the light BVH sorts: a row per emissive sphere, rectangle and mesh triangle, and each point
        and spot light (the environment, directional lights and the sun are infinitely far)."""
        from .emitters.kinds import KINDS

        return sum(_light_rows(o) for o in self.emitters) + sum(not KINDS[light.kind].infinite for light in self.lights)

    def light_table(self):
        """The light table (:class:`~lightprobe.emitters.kinds.LightArrays`, world space) of the scene's emissive
        objects and lights: :func:`lightprobe.emitters.table.light_table`."""
        from .emitters.table import light_table

        return light_table(self.emitters, self.lights, environment=self.environment is not None)

    def summary(self) -> str:
        w, h = self.camera.resolution
        lights = []
        if self.environment is not None:
            lights.append(self.environment.source)
        if self.emitters:
            n = sum(_light_rows(o) for o in self.emitters)
            lights.append(f"{n} area lights")
        for kind in ("point", "spot", "directional", "sun"):
            n = sum(light.kind == kind for light in self.lights)
            if n:
                lights.append(f"{n} {kind} light{'s' if n > 1 else ''}")
        textured = self.texture_bytes
        textures = f" ({textured / 2**20:.1f} MiB of textures)" if textured else ""
        return (
            f"{self.name}: {len(self.objects)} objects ({self.triangle_count} triangles), "
            f"{len(self.materials)} materials{textures}, {w}x{h}, light {' + '.join(lights) or 'none'}"
        )


def _light_rows(obj: SceneObject) -> int:
    """Rows an emissive object takes in the light table: one per triangle of a mesh, else one."""
    return obj.shape.triangle_count if isinstance(obj.shape, TriangleMesh) else 1


def _emission(value, shape, label: str) -> np.ndarray | None:
    """RGB radiance (3,), or for a mesh also one per face (F, 3); None when it is black everywhere."""
    arr = numeric_array(value, f"{label}: emission", SceneError)
    if arr.ndim == 2 and isinstance(shape, TriangleMesh):
        if arr.shape != (shape.triangle_count, 3) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise SceneError(
                f"{label}: per-face emission must be ({shape.triangle_count}, 3) finite values >= 0, got {arr.shape}"
            )
        return arr if arr.max() > 0 else None
    try:
        rgb = rgb_param(arr, "emission")
    except LightprobeError as exc:
        raise SceneError(f"{label}: {exc}") from None
    return rgb if max(rgb.tolist()) > 0 else None


class _TextureRows:
    """The materials' textures in the kernels' layout (``SceneArrays.material_textured`` and after)."""

    def __init__(self, materials: list[BSDF]):
        from .textures import pack_textures
        from .textures.material_textures import USES

        k = len(materials)
        self.textured = np.zeros(k, np.int64)
        self.uses = np.full((k, len(USES)), -1, np.int64)
        self.normal_scale = np.ones(k)
        self.alpha = np.tile([-1.0, 1.0], (k, 1))
        rows: dict[int, int] = {}
        textures = []
        for i, material in enumerate(materials):
            if material.textures is None:
                continue
            self.textured[i] = 1
            self.normal_scale[i] = float(material.textures.normal_scale)
            if material.textures.masked:
                self.alpha[i] = material.textures.alpha_cutoff, material.textures.alpha_factor
            for use, texture in material.textures.used().items():
                if id(texture) not in rows:
                    rows[id(texture)] = len(textures)
                    textures.append(texture)
                self.uses[i, USES.index(use)] = rows[id(texture)]
        self.packed = pack_textures(textures)

    @staticmethod
    def proxy_spheres(mesh: TriangleMesh, material: BSDF) -> np.ndarray:
        """The mesh's proxy spheres; without the inner ball if its material cuts holes in it."""
        from .geometry.proxies import NO_BALL

        if material.textures is None or not material.textures.masked:
            return mesh.spheres
        spheres = mesh.spheres.copy()
        spheres[4] = NO_BALL
        return spheres

    @staticmethod
    def tangents(mesh: TriangleMesh, material: BSDF) -> np.ndarray:
        """The mesh's tangents where its material has a normal map (generated if it stores none), else zeros."""
        from .geometry.mesh import angle_weighted_normals
        from .textures import generate_tangents

        if material.textures is None or material.textures.normal is None:
            return np.zeros((mesh.vertices.shape[0], 4))
        if mesh.tangents is not None:
            return mesh.tangents
        normals = mesh.normals if mesh.normals is not None else angle_weighted_normals(mesh.vertices, mesh.faces)
        return generate_tangents(mesh.vertices, mesh.faces, normals, mesh.uvs)
