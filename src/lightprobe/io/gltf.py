"""glTF 2.0 scenes (``.gltf`` with its buffers and images, or ``.glb``): meshes with their node transforms and
metallic-roughness materials, cameras and ``KHR_lights_punctual`` lights.

The JSON is read here and the accessors decoded with NumPy, as the specification lays them out (component type,
count, element type, byte offset and stride, normalized integers); trimesh's glTF loader rounds base colours to 8
bits and does not say which material a primitive had, so it serves to write test assets and to cross-check the
geometry, not to read (decisions.md 84).

What becomes what:

- every node of the default scene (``scene``, else the first), with its world transform (``matrix`` or
  translation x rotation x scale, parents first), that holds a mesh: one lightprobe mesh per triangle primitive,
  with the file's normals (else flat), in the node's world frame and then the include's ``transform``;
- a primitive's material: :class:`~lightprobe.bsdfs.MetallicRoughness` with ``baseColorFactor``, ``metallicFactor``,
  ``roughnessFactor`` (the specification's defaults 1, 1, 1, and its default material when there is none);
  ``emissiveFactor`` x ``KHR_materials_emissive_strength`` makes the primitive an area light; ``doubleSided``;
- textures (``lightprobe.textures``): ``baseColorTexture`` (sRGB), ``metallicRoughnessTexture`` (G roughness,
  B metallic), ``normalTexture`` with its ``scale``, with the sampler's ``wrapS`` / ``wrapT`` and its ``magFilter``
  (nearest, else bilinear), on ``TEXCOORD_0`` and the file's ``TANGENT`` (generated when absent); images from files,
  data URIs or buffer views, decoded by OpenImageIO (8-bit kept as bytes, 16-bit as float).  Fallbacks, each with a
  warning: an ``emissiveTexture`` gives each triangle the texture's mean over it (sRGB) x the emission (a triangle
  light's radiance is constant); ``occlusionTexture`` is ignored (the renderer computes occlusion); a ``texCoord``
  other than 0 reads ``TEXCOORD_0``; ``KHR_texture_transform`` (when not required) is ignored; ``BLEND`` is rendered as
  ``MASK`` at 0.5 (the renderer has no partial transparency);
- ``alphaMode`` ``MASK`` cuts the surface out where ``baseColorFactor``'s alpha x the base-colour texture's alpha
  is below ``alphaCutoff``, for camera, BSDF and shadow rays (``geometry/alpha_mask.py``);
- cameras (perspective): :class:`~lightprobe.geometry.Camera` at the node, looking down its -Z with +Y up, ``yfov``
  vertical; orthographic cameras are refused by name;
- ``KHR_lights_punctual``: point (intensity in candela, taken as W/sr), spot (cone angles), directional (lux, as
  W/m^2, a delta light); ``range`` is ignored with a warning.

Refused, each in one line naming the file and the item: a missing or short buffer, a data URI that is not base64,
``extensionsRequired`` outside what is read here (Draco: ``KHR_draco_mesh_compression``, by name), primitives that
are not triangles (points, lines, strips and fans), sparse accessors, vertex indices out of range, a missing or
corrupt image, a textured primitive without ``TEXCOORD_0``; and, checked for the whole file when it is read, any index
of the file (a scene's nodes, a node's mesh, camera, children or light, a primitive's accessors and material, an
accessor's buffer view, a view's buffer, a material's textures, a texture's image and sampler, ...) that is not a
whole number or names an item that does not exist (``meshes[2].primitives[0].attributes.POSITION: accessor 9 does
not exist``).
"""

from __future__ import annotations

import base64
import json
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import LightprobeError, SceneError, warn_once
from ..textures.image_texture import triangle_means

__all__ = ["GltfAsset", "load_gltf"]

SUPPORTED_REQUIRED = {"KHR_lights_punctual", "KHR_materials_emissive_strength"}
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_MODES = {0: "points", 1: "lines", 2: "line loop", 3: "line strip", 4: "triangles", 5: "triangle strip", 6: "fan"}


@dataclass
class GltfMesh:
    """One triangle primitive in world space, with its material and emission."""

    mesh: object  # TriangleMesh
    material: object  # MetallicRoughness
    name: str
    two_sided: bool
    emission: np.ndarray | None = None


@dataclass
class GltfAsset:
    path: Path
    meshes: list[GltfMesh] = field(default_factory=list)
    cameras: dict = field(default_factory=dict)  # name -> (origin, target, up, yfov degrees)
    lights: list = field(default_factory=list)

    def add_to(self, scene, *, name: str | None = None) -> None:
        """Add the meshes (with their materials) and the lights to ``scene``."""
        prefix = name or self.path.name
        for item in self.meshes:
            scene.add(item.mesh, item.material, two_sided=item.two_sided, name=f"{prefix}: {item.name}",
                      emission=item.emission)  # fmt: skip
        for light in self.lights:
            scene.add_light(light)

    def camera(self, name: str, resolution):
        """The file's camera ``name`` as a lightprobe Camera of ``resolution``."""
        from ..geometry import Camera

        if name not in self.cameras:
            known = ", ".join(self.cameras) or "none"
            raise SceneError(f"{self.path}: no camera named {name!r} (cameras: {known})")
        origin, target, up, fov = self.cameras[name]
        return Camera(origin, target, up, fov=fov, resolution=resolution)


#: every index a glTF 2.0 file holds: (top-level array, the path of the index in each of its items, the array it
#: indexes). In a path, ``name[]`` is each item of a list, ``*`` each value of an object, and a trailing ``!`` an
#: index the specification requires wherever its object is present.
_REFERENCES = (
    ("scenes", "nodes[]", "nodes"),
    ("nodes", "children[]", "nodes"),
    ("nodes", "mesh", "meshes"),
    ("nodes", "camera", "cameras"),
    ("nodes", "skin", "skins"),
    ("nodes", "extensions.KHR_lights_punctual.light!", "lights"),
    ("meshes", "primitives[].attributes.*", "accessors"),
    ("meshes", "primitives[].indices", "accessors"),
    ("meshes", "primitives[].material", "materials"),
    ("meshes", "primitives[].targets[].*", "accessors"),
    ("accessors", "bufferView", "bufferViews"),
    ("accessors", "sparse.indices.bufferView!", "bufferViews"),
    ("accessors", "sparse.values.bufferView!", "bufferViews"),
    ("bufferViews", "buffer!", "buffers"),
    ("images", "bufferView", "bufferViews"),
    ("textures", "source", "images"),
    ("textures", "sampler", "samplers"),
    ("materials", "pbrMetallicRoughness.baseColorTexture.index!", "textures"),
    ("materials", "pbrMetallicRoughness.metallicRoughnessTexture.index!", "textures"),
    ("materials", "normalTexture.index!", "textures"),
    ("materials", "occlusionTexture.index!", "textures"),
    ("materials", "emissiveTexture.index!", "textures"),
    ("skins", "inverseBindMatrices", "accessors"),
    ("skins", "skeleton", "nodes"),
    ("skins", "joints[]", "nodes"),
    ("animations", "channels[].target.node", "nodes"),
    ("animations", "samplers[].input!", "accessors"),
    ("animations", "samplers[].output!", "accessors"),
)
#: what one item of each array is called in a message
_ITEM = {"scenes": "scene", "nodes": "node", "meshes": "mesh", "cameras": "camera", "skins": "skin",
         "lights": "light", "accessors": "accessor", "materials": "material", "bufferViews": "bufferView",
         "buffers": "buffer", "images": "image", "textures": "texture", "samplers": "sampler",
         "animations": "animation"}  # fmt: skip


def _check_indices(doc: dict, path: Path) -> None:
    """Every index of the file names an item that exists, and every array and object on the way to one is one: a
    :class:`SceneError` naming the file and the item otherwise (``meshes[2].primitives[0].attributes.POSITION:
    accessor 9 does not exist``), so that nothing after the load meets an index out of range."""

    def fail(where: str, what: str):
        raise SceneError(f"{path}: {where}: {what}")

    def array(holder: dict, key: str, where: str) -> list:
        value = holder.get(key, [])
        if not isinstance(value, list):
            fail(where, "not a list")
        for i, item in enumerate(value):
            if not isinstance(item, dict):
                fail(f"{where}[{i}]", "not an object")
        return value

    def table(holder: dict, key: str, where: str) -> dict:
        value = holder.get(key, {})
        if not isinstance(value, dict):
            fail(where, "not an object")
        return value

    lights = table(table(doc, "extensions", "extensions"), "KHR_lights_punctual", "extensions.KHR_lights_punctual")
    arrays = {name: array(doc, name, name) for name in _ITEM if name != "lights"}
    arrays["lights"] = array(lights, "lights", "extensions.KHR_lights_punctual.lights")

    def check(value, where: str, target: str, count: int) -> None:
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            fail(where, f"{value!r} is not an index (a whole number from 0)")
        if value >= count:
            fail(where, f"{_ITEM[target]} {value} does not exist")

    def follow(value, steps: list[str], where: str, target: str, count: int) -> None:
        """The indices at ``steps`` below ``value`` (found at ``where``)."""
        if not steps:
            check(value, where, target, count)
            return
        step, rest = steps[0], steps[1:]
        if step == "*":
            if not isinstance(value, dict):
                fail(where, "not an object")
            for key, item in value.items():
                follow(item, rest, f"{where}.{key}", target, count)
            return
        if not isinstance(value, dict):
            fail(where, "not an object")
        key, required = step.removesuffix("[]").removesuffix("!"), step.endswith("!")
        if key not in value:
            if required:
                fail(f"{where}.{key}", "missing")
            return
        if step.endswith("[]"):
            items = value[key]
            if not isinstance(items, list):
                fail(f"{where}.{key}", "not a list")
            for i, item in enumerate(items):
                follow(item, rest, f"{where}.{key}[{i}]", target, count)
        else:
            follow(value[key], rest, f"{where}.{key}", target, count)

    for name, reference, target in _REFERENCES:
        for i, item in enumerate(arrays[name]):
            follow(item, reference.split("."), f"{name}[{i}]", target, len(arrays[target]))
    for i, animation in enumerate(arrays["animations"]):  # a channel's sampler is one of its animation's
        samplers = animation.get("samplers", [])
        for j, channel in enumerate(animation.get("channels", [])):
            follow(channel, ["sampler!"], f"animations[{i}].channels[{j}]", "samplers", len(samplers))
    if "scene" in doc:
        check(doc["scene"], "scene", "scenes", len(arrays["scenes"]))


class _Reader:
    def __init__(self, path: Path):
        self.path = path
        try:
            raw = path.read_bytes()
        except FileNotFoundError:
            raise SceneError(f"{path}: no such file") from None
        except OSError as exc:
            raise SceneError(f"{path}: cannot be read ({exc.strerror})") from None
        self.blob = None
        if raw[:4] == b"glTF":
            self.doc, self.blob = self._glb(raw)
        else:
            try:
                self.doc = json.loads(raw.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise SceneError(f"{path}: not glTF (neither a GLB file nor JSON: {exc})") from None
        if not isinstance(self.doc, dict) or not isinstance(self.doc.get("asset"), dict):
            raise SceneError(f"{path}: not glTF (no 'asset' object)")
        version = str(self.doc["asset"].get("version", ""))
        if not version.startswith("2."):
            raise SceneError(f"{path}: glTF version {version!r}; only 2.x is read")
        required = set(self.doc.get("extensionsRequired", []))
        if "KHR_draco_mesh_compression" in required:
            raise SceneError(f"{path}: Draco-compressed meshes (KHR_draco_mesh_compression) are not supported; "
                             "export without compression")  # fmt: skip
        unsupported = sorted(required - SUPPORTED_REQUIRED)
        if unsupported:
            raise SceneError(f"{path}: requires unsupported extension(s) {', '.join(unsupported)}")
        _check_indices(self.doc, path)  # once, here: every lookup below may trust the file's indices
        self._buffers: dict[int, bytes] = {}
        self._textures: dict[int, object] = {}

    def _glb(self, raw: bytes):
        if len(raw) < 20:
            raise SceneError(f"{self.path}: truncated GLB header")
        _, version, length = struct.unpack_from("<4sII", raw, 0)
        if version != 2:
            raise SceneError(f"{self.path}: GLB version {version}; only 2 is read")
        if length > len(raw):
            raise SceneError(f"{self.path}: truncated GLB ({len(raw)} of {length} bytes)")
        offset, doc, blob = 12, None, None
        while offset + 8 <= length:
            size, kind = struct.unpack_from("<II", raw, offset)
            chunk = raw[offset + 8 : offset + 8 + size]
            if len(chunk) < size:
                raise SceneError(f"{self.path}: truncated GLB chunk")
            if kind == 0x4E4F534A:  # JSON
                try:
                    doc = json.loads(chunk.decode("utf-8"))
                except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                    raise SceneError(f"{self.path}: the GLB's JSON chunk is corrupt ({exc})") from None
            elif kind == 0x004E4942 and blob is None:  # BIN
                blob = chunk
            offset += 8 + size + (-size % 4)
        if doc is None:
            raise SceneError(f"{self.path}: GLB without a JSON chunk")
        return doc, blob

    def buffer(self, index: int) -> bytes:
        if index in self._buffers:
            return self._buffers[index]
        spec = self.doc["buffers"][index]  # an index that _check_indices has seen
        uri = spec.get("uri")
        if uri is None:
            if self.blob is None:
                raise SceneError(f"{self.path}: buffer {index} has no uri and the file has no binary chunk")
            data = self.blob
        elif uri.startswith("data:"):
            data, _ = self._data_uri(uri, f"buffer {index}")
        else:
            file = self.path.parent / uri
            try:
                data = file.read_bytes()
            except FileNotFoundError:
                raise SceneError(f"{file}: no such file (buffer {index} of {self.path.name})") from None
        if len(data) < spec.get("byteLength", 0):
            source = "binary chunk" if uri is None else ("data URI" if uri.startswith("data:") else uri)
            raise SceneError(f"{self.path}: buffer {index} ({source}) holds {len(data)} bytes, "
                             f"expected {spec['byteLength']}")  # fmt: skip
        self._buffers[index] = data
        return data

    def accessor(self, index: int, what: str) -> np.ndarray:
        """Accessor ``index`` as an (count, width) float64 or int64 array."""
        acc = self.doc["accessors"][index]  # an index that _check_indices has seen
        if "sparse" in acc:
            raise SceneError(f"{self.path}: {what}: sparse accessors are not supported")
        dtype = _COMPONENTS.get(acc.get("componentType"))
        width = _WIDTH.get(acc.get("type"))
        if dtype is None or width is None:
            raise SceneError(f"{self.path}: {what}: accessor {index} has an unknown component or element type")
        count = int(acc.get("count", 0))
        if "bufferView" not in acc:
            return np.zeros((count, width))
        view = self.doc["bufferViews"][acc["bufferView"]]
        data = self.buffer(view["buffer"])
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        item = np.dtype(dtype).itemsize * width
        stride = view.get("byteStride") or item
        end = start + (count - 1) * stride + item if count else start
        if end > view.get("byteOffset", 0) + view["byteLength"] or end > len(data):
            raise SceneError(f"{self.path}: {what}: accessor {index} runs past its buffer view")
        if stride == item:
            array = np.frombuffer(data, dtype=dtype, count=count * width, offset=start).reshape(count, width)
        else:
            rows = np.lib.stride_tricks.as_strided(
                np.frombuffer(data, dtype=np.uint8, offset=start), shape=(count, item), strides=(stride, 1)
            )
            array = np.ascontiguousarray(rows).view(dtype).reshape(count, width)
        if acc.get("normalized") and dtype is not np.float32:
            info = np.iinfo(dtype)
            return np.maximum(array.astype(np.float64) / info.max, -1.0)
        return array.astype(np.float64 if dtype is np.float32 else np.int64)

    def texture(self, info: dict, what: str):
        """The ImageTexture of a material's texture reference ``info`` (``{"index": ...}``), read once per
        texture."""
        from ..textures import ImageTexture

        index = info["index"]  # an index that _check_indices has seen, as every index below
        if info.get("texCoord", 0) != 0:
            warn_once(f"{self.path}: {what}: texCoord {info['texCoord']} is read as TEXCOORD_0")
        if "KHR_texture_transform" in info.get("extensions", {}):
            warn_once(f"{self.path}: {what}: KHR_texture_transform is ignored")
        if index in self._textures:
            return self._textures[index]
        spec = self.doc["textures"][index]
        source = spec.get("source")
        if source is None:  # an image only an extension gives (KHR_texture_basisu ...)
            raise SceneError(f"{self.path}: {what}: texture {index} has no image (no source)")
        sampler = self.doc["samplers"][spec["sampler"]] if "sampler" in spec else {}
        wrap = tuple(_WRAPS.get(sampler.get(key, 10497), "repeat") for key in ("wrapS", "wrapT"))
        filter = "nearest" if sampler.get("magFilter") == 9728 else "linear"
        image = self.doc["images"][source]
        label = f"{self.path}: image {source}" + (f" ({image['name']})" if image.get("name") else "")
        try:
            if "uri" in image and not image["uri"].startswith("data:"):
                file = self.path.parent / image["uri"]
                texture = ImageTexture.read(file, wrap=wrap, filter=filter, name=f"{file} (image {source} of "
                                            f"{self.path.name})")  # fmt: skip
            else:
                data, mime = self._image_bytes(image, source)
                texture = ImageTexture.from_bytes(data, suffix=_SUFFIXES.get(mime, ".png"), wrap=wrap, filter=filter,
                                                  name=label)  # fmt: skip
        except LightprobeError as exc:
            raise SceneError(str(exc)) from None
        self._textures[index] = texture
        return texture

    def _data_uri(self, uri: str, what: str) -> tuple[bytes, str]:
        """The bytes and media type of a base64 data URI (``data:image/png;base64,...``)."""
        head, _, payload = uri.partition(",")
        if not head.endswith(";base64"):
            raise SceneError(f"{self.path}: {what}: only base64 data URIs are read")
        return base64.b64decode(payload), head[5:].split(";")[0]

    def _image_bytes(self, image: dict, source: int) -> tuple[bytes, str]:
        if "uri" in image:
            return self._data_uri(image["uri"], f"image {source}")
        if "bufferView" not in image:
            raise SceneError(f"{self.path}: image {source} has neither a uri nor a buffer view")
        view = self.doc["bufferViews"][image["bufferView"]]
        data = self.buffer(view["buffer"])
        start = view.get("byteOffset", 0)
        return data[start : start + view["byteLength"]], image.get("mimeType", "image/png")


_WRAPS = {10497: "repeat", 33648: "mirrored_repeat", 33071: "clamp"}
_SUFFIXES = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp", "image/ktx2": ".ktx2"}


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major in the file
    t = np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
    x, y, z, w = (float(c) for c in node.get("rotation", [0.0, 0.0, 0.0, 1.0]))
    s = np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip
    m = np.eye(4)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m


def _world_nodes(doc: dict, path: Path):
    """(node index, world matrix) of every node of the default scene, parents before children."""
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes")
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:  # no scene: every node that is nobody's child
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    out, stack, seen = [], [(r, np.eye(4)) for r in reversed(roots)], set()
    while stack:
        index, parent = stack.pop()
        if index in seen:
            raise SceneError(f"{path}: node {index} is its own ancestor (the node graph has a cycle)")
        seen.add(index)
        world = parent @ _node_matrix(nodes[index])
        out.append((index, world))
        stack.extend((c, world) for c in reversed(nodes[index].get("children", [])))
    return out


def _material(reader: _Reader, index: int | None, where: str):
    """(material, emission, two-sided) of material ``index`` (None: the specification's default); the emission is
    None, RGB, or (RGB, emissive texture) for the caller to take the texture's mean over each triangle."""
    from ..bsdfs import MetallicRoughness
    from ..textures import MaterialTextures

    doc, path = reader.doc, reader.path
    if index is None:
        return MetallicRoughness(1.0, 1.0, 1.0), None, False
    spec = doc["materials"][index]  # an index that _check_indices has seen
    name = spec.get("name") or f"material {index}"
    what = f"material {name!r}"
    pbr = spec.get("pbrMetallicRoughness", {})
    base = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
    alpha_mode = spec.get("alphaMode", "OPAQUE")
    if alpha_mode not in ("OPAQUE", "MASK", "BLEND"):
        raise SceneError(f"{path}: {what}: unknown alphaMode {alpha_mode!r}")
    if alpha_mode == "BLEND":
        warn_once(f"{path}: {what}: alphaMode BLEND is rendered as MASK with cutoff 0.5 (no partial transparency)")
    if "occlusionTexture" in spec:
        warn_once(f"{path}: {what}: occlusionTexture is ignored (the renderer computes occlusion by tracing rays)")
    uses = {}
    for use, holder, key in (("base_color", pbr, "baseColorTexture"),
                             ("metallic_roughness", pbr, "metallicRoughnessTexture"),
                             ("normal", spec, "normalTexture")):  # fmt: skip
        if key in holder:
            uses[use] = reader.texture(holder[key], f"{what} {key}")
    scale = float(spec.get("normalTexture", {}).get("scale", 1.0))
    try:
        alpha = {}
        if alpha_mode != "OPAQUE":
            cutoff = spec.get("alphaCutoff", 0.5) if alpha_mode == "MASK" else 0.5
            alpha = {
                "alpha_mode": "mask",
                "alpha_cutoff": cutoff,
                "alpha_factor": float(base[3]) if len(base) > 3 else 1.0,
            }
        textures = MaterialTextures(**uses, normal_scale=scale, **alpha) if uses or alpha else None
        material = MetallicRoughness(base[:3], pbr.get("metallicFactor", 1.0), pbr.get("roughnessFactor", 1.0),
                                     textures=textures)  # fmt: skip
    except LightprobeError as exc:
        raise SceneError(f"{path}: {where}: {what}: {exc}") from None
    emissive = np.asarray(spec.get("emissiveFactor", [0.0, 0.0, 0.0]), dtype=np.float64)
    strength = spec.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    emission = emissive * float(strength) if np.any(emissive > 0) else None
    if emission is not None and "emissiveTexture" in spec:
        emissive_texture = reader.texture(spec["emissiveTexture"], f"{what} emissiveTexture")
        warn_once(f"{path}: {what}: emissiveTexture is applied as its mean over each triangle (a triangle light's "
                  "radiance is constant)")  # fmt: skip
        emission = (emission, emissive_texture)
    return material, emission, bool(spec.get("doubleSided", False))


def load_gltf(path, *, transform=None) -> GltfAsset:
    """Read a glTF 2.0 file; ``transform`` (4x4 or a scene-file transform table) places the whole asset."""
    from ..geometry.mesh import TriangleMesh
    from ..geometry.transform import make_transform

    file = Path(path)
    reader = _Reader(file)
    doc = reader.doc
    place = np.asarray(transform, dtype=np.float64) if isinstance(transform, np.ndarray) else make_transform(transform)
    asset = GltfAsset(file)
    lights = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    for node_index, world in _world_nodes(doc, file):
        node = doc["nodes"][node_index]
        matrix = place @ world
        if "mesh" in node:
            mesh_spec = doc["meshes"][node["mesh"]]
            mesh_name = mesh_spec.get("name") or f"mesh {node['mesh']}"
            for k, prim in enumerate(mesh_spec.get("primitives", [])):
                where = f"mesh {mesh_name!r} primitive {k}"
                mode = prim.get("mode", 4)
                if mode != 4:
                    raise SceneError(f"{file}: {where} is {_MODES.get(mode, f'mode {mode}')}; only triangles are "
                                     "read (re-export with triangulation)")  # fmt: skip
                attributes = prim.get("attributes", {})
                if "POSITION" not in attributes:
                    raise SceneError(f"{file}: {where} has no POSITION")
                vertices = reader.accessor(attributes["POSITION"], where)
                normals = reader.accessor(attributes["NORMAL"], where) if "NORMAL" in attributes else None
                if "indices" in prim:
                    faces = reader.accessor(prim["indices"], where).reshape(-1)
                else:
                    faces = np.arange(vertices.shape[0])
                if faces.size % 3:
                    raise SceneError(f"{file}: {where}: {faces.size} indices are not whole triangles")
                if faces.size and (faces.min() < 0 or faces.max() >= vertices.shape[0]):
                    raise SceneError(f"{file}: {where}: indices out of range (0 to {vertices.shape[0] - 1})")
                label = f"{mesh_name}" + (f" #{k}" if len(mesh_spec["primitives"]) > 1 else "")
                material, emission, two_sided = _material(reader, prim.get("material"), where)
                uvs = tangents = None
                sampled = isinstance(emission, tuple) or (material.textures is not None and material.textures.used())
                if sampled and "TEXCOORD_0" not in attributes:
                    raise SceneError(f"{file}: {where}: its material has textures but it has no TEXCOORD_0")
                if material.textures is not None or isinstance(emission, tuple):
                    uvs = (reader.accessor(attributes["TEXCOORD_0"], f"{where} TEXCOORD_0")[:, :2]
                           if "TEXCOORD_0" in attributes else np.zeros((vertices.shape[0], 2)))  # fmt: skip
                    if (
                        material.textures is not None
                        and material.textures.normal is not None
                        and "TANGENT" in attributes
                    ):
                        tangents = reader.accessor(attributes["TANGENT"], f"{where} TANGENT")
                    if uvs.shape[0] != vertices.shape[0] or (
                        tangents is not None and tangents.shape != (vertices.shape[0], 4)
                    ):
                        raise SceneError(f"{file}: {where}: TEXCOORD_0 or TANGENT does not have one VEC2 / VEC4 "
                                         "per vertex")  # fmt: skip
                mesh = TriangleMesh.from_arrays(vertices, faces.reshape(-1, 3), normals, smooth=False,
                                                name=f"{file.name}: {label}", uvs=uvs,
                                                tangents=tangents)  # fmt: skip
                if isinstance(emission, tuple):  # (factor, texture): one radiance per face
                    factor, texture = emission
                    emission = factor * triangle_means(texture, mesh.uvs[mesh.faces], srgb=True)
                    emission = emission if np.any(emission > 0) else None
                asset.meshes.append(GltfMesh(mesh.transformed(matrix), material, label, two_sided, emission))
        if "camera" in node:
            spec = doc["cameras"][node["camera"]]
            name = spec.get("name") or f"camera {node['camera']}"
            if spec.get("type") != "perspective":
                raise SceneError(f"{file}: camera {name!r} is {spec.get('type')}; only perspective cameras are read")
            origin = matrix[:3, 3]
            forward = -matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])
            up = matrix[:3, 1] / np.linalg.norm(matrix[:3, 1])
            fov = math.degrees(float(spec["perspective"]["yfov"]))
            asset.cameras[name] = (origin, origin + forward, up, fov)
        light_ref = node.get("extensions", {}).get("KHR_lights_punctual", {}).get("light")
        if light_ref is not None:
            asset.lights.append(_light(lights, light_ref, matrix, file))
    if not asset.meshes and not asset.lights:
        raise SceneError(f"{file}: no triangle meshes or lights in its scene")
    return asset


def _light(lights: list, index: int, matrix: np.ndarray, path: Path):
    from ..emitters.directional import DirectionalLight
    from ..emitters.punctual import PointLight, SpotLight

    spec = lights[index]  # an index that _check_indices has seen
    name = spec.get("name") or f"light {index}"
    color = np.asarray(spec.get("color", [1.0, 1.0, 1.0]), dtype=np.float64)
    power = color * float(spec.get("intensity", 1.0))
    if "range" in spec:
        warn_once(f"{path}: light {name!r}: range is ignored (lights fall off with the inverse square)")
    position = matrix[:3, 3]
    direction = -matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])  # lights shine down the node's -Z
    kind = spec.get("type")
    try:
        if kind == "point":
            return PointLight(position, power)
        if kind == "spot":
            spot = spec.get("spot", {})
            outer = math.degrees(float(spot.get("outerConeAngle", math.pi / 4)))
            inner = math.degrees(float(spot.get("innerConeAngle", 0.0)))
            return SpotLight(position, position + direction, power, cone_angle=outer, falloff_start=inner)
        if kind == "directional":
            return DirectionalLight(direction, power)
    except Exception as exc:
        raise SceneError(f"{path}: light {name!r}: {exc}") from None
    raise SceneError(f"{path}: light {name!r} has unknown type {kind!r}")
