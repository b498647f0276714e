"""glTF 2.0 import: node transforms, materials, cameras and lights read exactly; a round trip through trimesh's
writer; every refused input one line naming the file and the item; a glTF render z-test-equal to the same scene
written in TOML."""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import numpy as np
import pytest

from lightprobe.bsdfs import MetallicRoughness
from lightprobe.errors import SceneError
from lightprobe.io.gltf import load_gltf

QUAD = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32)
QUAD_FACES = np.array([[0, 2, 1], [0, 3, 2]], np.uint16)  # facing +Y


def write_gltf(path: Path, doc_changes: dict | None = None, *, primitive_changes: dict | None = None, glb=False):
    """A one-quad glTF: a parent node (translation, rotation 90 degrees about +Y, scale 2) whose child holds the
    mesh; a camera, three KHR_lights_punctual lights, one material; the buffer a data URI (or GLB's chunk)."""
    blob = QUAD.tobytes() + np.tile([0, 1, 0], (4, 1)).astype(np.float32).tobytes() + QUAD_FACES.tobytes()
    half = math.sqrt(0.5)
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 2, 3, 4, 5]}],
        "nodes": [
            {"translation": [1.0, 2.0, 3.0], "rotation": [0.0, half, 0.0, half], "scale": [2.0, 2.0, 2.0],
             "children": [1]},
            {"mesh": 0, "translation": [0.0, 0.5, 0.0]},
            {"camera": 0, "name": "cam node", "translation": [0.0, 1.0, 5.0]},
            {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0.0, 3.0, 0.0]},
            {"extensions": {"KHR_lights_punctual": {"light": 1}}, "translation": [1.0, 3.0, 0.0],
             "rotation": [-half, 0.0, 0.0, half]},
            {"extensions": {"KHR_lights_punctual": {"light": 2}}, "rotation": [-half, 0.0, 0.0, half]},
        ],
        "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2,
                                                    "material": 0}]}],
        "materials": [{"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.5, 0.7, 1.0],
                       "metallicFactor": 0.25, "roughnessFactor": 0.6}, "doubleSided": True,
                       "emissiveFactor": [1.0, 0.5, 0.25],
                       "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}}],
        "cameras": [{"name": "Main", "type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "intensity": 20.0, "color": [1.0, 0.5, 0.5]},
            {"type": "spot", "intensity": 30.0, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.4}},
            {"type": "directional", "intensity": 3.0}]}},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 48},
            {"buffer": 0, "byteOffset": 96, "byteLength": 12},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
    }  # fmt: skip
    doc.update(doc_changes or {})
    doc["meshes"][0]["primitives"][0].update(primitive_changes or {})
    if glb:
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        data = blob + b"\0" * (-len(blob) % 4)
        body = struct_chunk(text, 0x4E4F534A) + struct_chunk(data, 0x004E4942)
        path.write_bytes(b"glTF" + (2).to_bytes(4, "little") + (12 + len(body)).to_bytes(4, "little") + body)
    else:
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        path.write_text(json.dumps(doc))
    return path


def struct_chunk(data: bytes, kind: int) -> bytes:
    return len(data).to_bytes(4, "little") + kind.to_bytes(4, "little") + data


@pytest.mark.parametrize("glb", [False, True])
def test_nodes_materials_cameras_and_lights(tmp_path, glb):
    asset = load_gltf(write_gltf(tmp_path / ("a.glb" if glb else "a.gltf"), glb=glb))
    (item,) = asset.meshes
    # child at (0, 0.5, 0), under scale 2, a quarter turn about +Y and a translation (1, 2, 3): x -> -z
    m = item.mesh
    expected = np.array([[-1, 0.5, -1], [1, 0.5, -1], [1, 0.5, 1], [-1, 0.5, 1]]) * 2.0
    expected = np.stack([expected[:, 2], expected[:, 1], -expected[:, 0]], axis=1) + np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(m.vertices, expected, atol=1e-6)
    np.testing.assert_allclose(m.normals, np.tile([0.0, 1.0, 0.0], (4, 1)), atol=1e-12)
    mat = item.material
    assert isinstance(mat, MetallicRoughness)
    assert mat.base_color.tolist() == [0.3, 0.5, 0.7] and mat.metallic == 0.25 and mat.roughness == 0.6
    assert item.two_sided and item.emission.tolist() == [4.0, 2.0, 1.0]
    origin, target, up, fov = asset.cameras["Main"]
    assert (
        origin.tolist() == [0.0, 1.0, 5.0] and np.allclose(target - origin, [0, 0, -1]) and np.allclose(up, [0, 1, 0])
    )
    assert fov == pytest.approx(math.degrees(0.5))
    point, spot, sun = asset.lights
    assert point.position.tolist() == [0.0, 3.0, 0.0] and np.allclose(point.radiance, [20.0, 10.0, 10.0])
    assert np.allclose(spot.axis, [0.0, -1.0, 0.0]) and spot.cone_angle == pytest.approx(math.degrees(0.4))
    assert spot.falloff_start == pytest.approx(math.degrees(0.2))
    assert np.allclose(sun.direction, [0.0, -1.0, 0.0])


def test_round_trip_through_trimesh(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    from trimesh.visual.material import PBRMaterial

    box = trimesh.creation.box(extents=[1.0, 2.0, 0.5])
    ball = trimesh.creation.icosphere(2, radius=0.7)
    box.visual = trimesh.visual.TextureVisuals(
        material=PBRMaterial(baseColorFactor=[255, 0, 0, 255], metallicFactor=0.0, roughnessFactor=0.5)
    )
    ball.visual = trimesh.visual.TextureVisuals(
        material=PBRMaterial(baseColorFactor=[255, 204, 51, 255], metallicFactor=1.0, roughnessFactor=0.2)
    )
    scene = trimesh.Scene()
    rotation = trimesh.transformations.rotation_matrix(0.6, [0.2, 1.0, 0.1])
    scene.add_geometry(box, node_name="box", transform=trimesh.transformations.translation_matrix([1, 0, 0]))
    scene.add_geometry(ball, node_name="ball", transform=rotation @ np.diag([1.5, 1.5, 1.5, 1.0]))
    for name in ("s.glb", "s.gltf"):
        scene.export(tmp_path / name)
        asset = load_gltf(tmp_path / name)
        ours = np.concatenate([m.mesh.vertices for m in asset.meshes])
        theirs = np.concatenate([g.vertices for g in scene.dump()])
        np.testing.assert_allclose(np.sort(ours, axis=0), np.sort(theirs, axis=0), atol=1e-5)
        assert sum(m.mesh.faces.shape[0] for m in asset.meshes) == sum(g.faces.shape[0] for g in scene.dump())
        metallic = sorted(m.material.metallic for m in asset.meshes)
        assert metallic == [0.0, 1.0]


@pytest.mark.parametrize(
    ("changes", "primitive", "message"),
    [
        ({"extensionsRequired": ["KHR_draco_mesh_compression"]}, None, "Draco-compressed meshes"),
        ({"extensionsRequired": ["EXT_meshopt_compression"]}, None, "unsupported extension(s) EXT_meshopt_compression"),
        (None, {"mode": 1}, "mesh 'quad' primitive 0 is lines; only triangles"),
        (None, {"attributes": {"NORMAL": 1}}, "has no POSITION"),
        ({"asset": {"version": "1.0"}}, None, "glTF version '1.0'"),
        ({"cameras": [{"type": "orthographic", "name": "o"}]}, None, "camera 'o' is orthographic"),
    ],
)
def test_refused_inputs_name_the_file_and_the_item(tmp_path, changes, primitive, message):
    path = write_gltf(tmp_path / "bad.gltf", changes, primitive_changes=primitive)
    with pytest.raises(SceneError, match=r"bad\.gltf") as info:
        load_gltf(path)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_missing_buffers_and_corrupt_files(tmp_path):
    path = write_gltf(tmp_path / "a.gltf")
    doc = json.loads(path.read_text())
    doc["buffers"][0]["uri"] = "missing.bin"
    path.write_text(json.dumps(doc))
    with pytest.raises(SceneError, match=r"missing\.bin: no such file \(buffer 0 of a\.gltf\)"):
        load_gltf(path)
    doc["buffers"][0]["uri"] = "short.bin"
    (tmp_path / "short.bin").write_bytes(b"\0" * 10)
    path.write_text(json.dumps(doc))
    with pytest.raises(SceneError, match="holds 10 bytes, expected 108"):
        load_gltf(path)
    (tmp_path / "c.gltf").write_text("{ not json")
    with pytest.raises(SceneError, match=r"c\.gltf: not glTF"):
        load_gltf(tmp_path / "c.gltf")
    glb = write_gltf(tmp_path / "t.glb", glb=True)
    glb.write_bytes(glb.read_bytes()[:40])
    with pytest.raises(SceneError, match=r"t\.glb: truncated"):
        load_gltf(glb)
    with pytest.raises(SceneError, match="no such file"):
        load_gltf(tmp_path / "none.glb")
    doc = json.loads(write_gltf(tmp_path / "i.gltf").read_text())
    doc["accessors"][2]["count"] = 9
    doc["bufferViews"][2]["byteLength"] = 18
    (tmp_path / "i.gltf").write_text(json.dumps(doc))
    with pytest.raises(SceneError, match="runs past its buffer"):
        load_gltf(tmp_path / "i.gltf")


def _set(doc: dict, where: str, value) -> None:
    """Set the item at ``where`` (``meshes[0].primitives[0].attributes.POSITION``) of a glTF document."""
    import re

    steps = [int(k) if k.isdigit() else k for k in re.findall(r"[^.\[\]]+", where)]
    holder = doc
    for step in steps[:-1]:
        holder = holder[step]
    holder[steps[-1]] = value


@pytest.mark.parametrize(
    ("where", "value", "said"),
    [
        ("meshes[0].primitives[0].attributes.POSITION", 9, "accessor 9 does not exist"),
        ("meshes[0].primitives[0].indices", 3, "accessor 3 does not exist"),
        ("meshes[0].primitives[0].material", 1, "material 1 does not exist"),
        ("accessors[1].bufferView", 9, "bufferView 9 does not exist"),
        ("bufferViews[2].buffer", 4, "buffer 4 does not exist"),
        ("nodes[1].mesh", 2, "mesh 2 does not exist"),
        ("nodes[0].children[0]", 6, "node 6 does not exist"),
        ("nodes[2].camera", 1, "camera 1 does not exist"),
        ("nodes[3].extensions.KHR_lights_punctual.light", 3, "light 3 does not exist"),
        ("scenes[0].nodes[4]", 17, "node 17 does not exist"),
        ("scene", 1, "scene 1 does not exist"),
        ("nodes[1].mesh", -1, "-1 is not an index (a whole number from 0)"),
        ("nodes[1].mesh", "0", "'0' is not an index (a whole number from 0)"),
        ("nodes[1].mesh", 0.0, "0.0 is not an index (a whole number from 0)"),
        ("nodes[1].mesh", True, "True is not an index (a whole number from 0)"),
        ("nodes[0].children", 1, "not a list"),
        ("nodes[5]", 5, "not an object"),
        ("meshes[0].primitives[0].attributes", [0, 1], "not an object"),
        ("accessors", {}, "not a list"),
        ("materials[0].normalTexture", {"scale": 2.0}, "missing"),
    ],
)
@pytest.mark.parametrize("glb", [False, True])
def test_every_index_is_checked_at_load(tmp_path, where, value, said, glb):
    """An index that names nothing (or is not an index) is one error naming the file and the item, found when the
    file is read: before, an accessor's buffer view, a node's mesh, children or camera, the default scene and a
    scene's nodes were looked up as they were met (an IndexError, a traceback), and the others named their item in
    words of their own."""
    path = tmp_path / ("bad.glb" if glb else "bad.gltf")
    write_gltf(path, glb=glb)
    doc = json.loads(path.read_text()) if not glb else None
    if glb:  # rewrite the JSON chunk
        raw = path.read_bytes()
        size = int.from_bytes(raw[12:16], "little")
        doc = json.loads(raw[20 : 20 + size])
    _set(doc, where, value)
    if glb:
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        rest = raw[20 + size :]
        body = struct_chunk(text, 0x4E4F534A) + rest
        path.write_bytes(b"glTF" + (2).to_bytes(4, "little") + (12 + len(body)).to_bytes(4, "little") + body)
    else:
        path.write_text(json.dumps(doc))
    with pytest.raises(SceneError) as info:
        load_gltf(path)
    expected = f"{path}: {where}: {said}" if said != "missing" else f"{path}: {where}.index: missing"
    assert str(info.value) == expected


def _png(path: Path, pixels: np.ndarray) -> bytes:
    import OpenImageIO as oiio

    h, w, c = pixels.shape
    fmt = oiio.UINT16 if pixels.dtype == np.uint16 else oiio.UINT8
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(pixels)
    out.close()
    return path.read_bytes()


def textured_gltf(tmp_path: Path, *, how: str = "file", tangents: bool = False) -> Path:
    """The quad of :func:`write_gltf` with TEXCOORD_0 (and TANGENT) and base colour, metallic-roughness and
    normal textures; the images as files next to it, data URIs, or buffer views of a second buffer."""
    rng = np.random.default_rng(11)
    base = rng.integers(0, 256, size=(3, 5, 4), dtype=np.uint8)  # odd sizes, with alpha
    mr = rng.integers(0, 65536, size=(4, 2, 3), dtype=np.uint16)  # 16 bits
    normal = np.tile(np.uint8([128, 128, 255]), (2, 2, 1))
    pngs = [_png(tmp_path / name, pixels) for name, pixels in (("base.png", base), ("mr.png", mr),
                                                               ("normal.png", normal))]  # fmt: skip
    uv = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, -1.5], [0.0, -1.5]], np.float32)  # out of [0, 1]: wrapped
    tangent = np.tile(np.float32([1.0, 0.0, 0.0, 1.0]), (4, 1))
    extra = uv.tobytes() + (tangent.tobytes() if tangents else b"")
    doc = {
        "images": [{"uri": "base.png"}, {"uri": "mr.png"}, {"uri": "normal.png"}],
        "samplers": [{"wrapS": 33648, "wrapT": 33071, "magFilter": 9728}],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1}, {"source": 2}],
    }
    path = write_gltf(tmp_path / "t.gltf")
    full = json.loads(path.read_text())
    full.update(doc)
    full["buffers"].append({"byteLength": len(extra), "uri": "data:application/octet-stream;base64,"
                            + base64.b64encode(extra).decode()})  # fmt: skip
    full["bufferViews"].append({"buffer": 1, "byteOffset": 0, "byteLength": len(extra)})
    full["accessors"].append({"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC2"})
    attributes = full["meshes"][0]["primitives"][0]["attributes"]
    attributes["TEXCOORD_0"] = 3
    if tangents:
        full["accessors"].append({"bufferView": 3, "byteOffset": 32, "componentType": 5126, "count": 4,
                                  "type": "VEC4"})  # fmt: skip
        attributes["TANGENT"] = 4
    material = full["materials"][0]
    material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    material["pbrMetallicRoughness"]["metallicRoughnessTexture"] = {"index": 1}
    material["normalTexture"] = {"index": 2, "scale": 0.5}
    if how == "data":
        for image, png in zip(full["images"], pngs, strict=True):
            image["uri"] = "data:image/png;base64," + base64.b64encode(png).decode()
    elif how == "view":
        offset = len(extra)
        blob = extra
        for image, png in zip(full["images"], pngs, strict=True):
            blob += png
            full["bufferViews"].append({"buffer": 1, "byteOffset": offset, "byteLength": len(png)})
            image.pop("uri")
            image.update(bufferView=len(full["bufferViews"]) - 1, mimeType="image/png")
            offset += len(png)
        full["buffers"][1] = {"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                              + base64.b64encode(blob).decode()}  # fmt: skip
    path.write_text(json.dumps(full))
    return path


@pytest.mark.parametrize("how", ["file", "data", "view"])
def test_textures_from_files_data_uris_and_buffer_views(tmp_path, how):
    asset = load_gltf(textured_gltf(tmp_path, how=how))
    (item,) = asset.meshes
    textures = item.material.textures
    assert textures.base_color.pixels.shape == (3, 5, 4) and not textures.base_color.is_float
    assert textures.base_color.wrap == ("mirrored_repeat", "clamp") and textures.base_color.filter == "nearest"
    assert textures.metallic_roughness.is_float and textures.metallic_roughness.wrap == ("repeat", "repeat")
    assert textures.normal_scale == 0.5 and textures.normal.filter == "linear"
    np.testing.assert_array_equal(item.mesh.uvs, [[0.0, 0.0], [2.0, 0.0], [2.0, -1.5], [0.0, -1.5]])
    assert item.mesh.tangents is None  # generated when the scene is compiled


def test_a_textured_gltf_renders_and_reads_its_tangents(tmp_path):
    """UVs outside [0, 1] wrap, the file's tangents are kept (turned with the node), the image is finite."""
    from lightprobe.emitters.envmap import EnvironmentMap
    from lightprobe.geometry import Camera
    from lightprobe.integrators import RenderSettings, render
    from lightprobe.scene import Scene

    asset = load_gltf(textured_gltf(tmp_path, tangents=True))
    # the node turns the quad a quarter turn about +Y: the tangent +x goes to -z
    np.testing.assert_allclose(asset.meshes[0].mesh.tangents, np.tile([0.0, 0.0, -1.0, 1.0], (4, 1)), atol=1e-6)
    scene = Scene(Camera([1.0, 6.0, 7.0], [1.0, 3.0, 3.0], fov=40.0, resolution=(16, 12)),
                  EnvironmentMap.from_array(np.full((8, 16, 3), 0.5)))  # fmt: skip
    asset.add_to(scene)
    image = render(scene, RenderSettings(spp=4)).image
    assert np.all(np.isfinite(image)) and image.max() > 0.0


def test_texture_inputs_refused_or_warned_in_one_line(tmp_path):
    path = textured_gltf(tmp_path)
    doc = json.loads(path.read_text())
    (tmp_path / "normal.png").unlink()
    with pytest.raises(SceneError, match=r"normal\.png \(image 2 of t\.gltf\): no such file") as info:
        load_gltf(path)
    assert "\n" not in str(info.value)
    (tmp_path / "normal.png").write_bytes(b"not a png at all")
    with pytest.raises(SceneError, match=r"normal\.png \(image 2 of t\.gltf\): cannot read image"):
        load_gltf(path)
    (tmp_path / "normal.png").write_bytes((tmp_path / "base.png").read_bytes())
    for change, message in (
        (lambda d: d["textures"][0].update(source=9), r"textures\[0\]\.source: image 9 does not exist"),
        (lambda d: d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"].update(index=7),
         r"materials\[0\]\.pbrMetallicRoughness\.baseColorTexture\.index: texture 7 does not exist"),
        (lambda d: d["textures"][0].pop("source"), "texture 0 has no image"),
        (lambda d: d["meshes"][0]["primitives"][0]["attributes"].pop("TEXCOORD_0"), "has textures but it has no "
         "TEXCOORD_0"),
    ):  # fmt: skip
        broken = json.loads(json.dumps(doc))
        change(broken)
        (tmp_path / "b.gltf").write_text(json.dumps(broken))
        with pytest.raises(SceneError, match=message) as info:
            load_gltf(tmp_path / "b.gltf")
        assert str(info.value).startswith(str(tmp_path / "b.gltf")) and "\n" not in str(info.value)
    doc["materials"][0]["occlusionTexture"] = {"index": 0}
    doc["materials"][0]["emissiveTexture"] = {"index": 1, "texCoord": 1}
    doc["materials"][0]["alphaMode"] = "BLEND"
    (tmp_path / "w.gltf").write_text(json.dumps(doc))
    with pytest.warns(UserWarning) as record:
        asset = load_gltf(tmp_path / "w.gltf")
    said = " | ".join(str(w.message) for w in record)
    for part in ("occlusionTexture is ignored", "texCoord 1 is read as TEXCOORD_0", "emissiveTexture is applied as "
                 "its mean over each triangle", "alphaMode BLEND is rendered as MASK"):  # fmt: skip
        assert part in said, said
    # per face: the emission x the sRGB-decoded texture's mean over the face (16 sub-triangle centroids)
    from lightprobe.textures.image_texture import triangle_means

    item = asset.meshes[0]
    means = triangle_means(item.material.textures.metallic_roughness, item.mesh.uvs[item.mesh.faces], srgb=True)
    assert item.emission.shape == (2, 3) and not np.allclose(means[0], means[1])
    np.testing.assert_allclose(item.emission, np.array([4.0, 2.0, 1.0]) * means)


def test_triangle_means_are_exact_for_a_texture_linear_across_the_triangle():
    from lightprobe.textures import ImageTexture
    from lightprobe.textures.image_texture import triangle_means

    width = 16
    ramp = np.tile(((np.arange(width) + 0.5) / width)[None, :, None], (4, 1, 3)).astype(np.float32)  # value = u
    triangles = np.array([[[0.1, 0.2], [0.9, 0.4], [0.3, 0.8]], [[0.05, 0.5], [0.5, 0.5], [0.2, 0.9]]])
    means = triangle_means(ImageTexture(ramp, wrap="clamp"), triangles, srgb=False)
    np.testing.assert_allclose(means, np.repeat(triangles[:, :, 0].mean(axis=1)[:, None], 3, axis=1), atol=1e-6)


def test_alpha_mask_reads_cutoff_and_factor(tmp_path):
    path = textured_gltf(tmp_path)
    doc = json.loads(path.read_text())
    material = doc["materials"][0]
    material.update(alphaMode="MASK", alphaCutoff=0.3)
    material["pbrMetallicRoughness"]["baseColorFactor"] = [0.3, 0.5, 0.7, 0.8]
    path.write_text(json.dumps(doc))
    textures = load_gltf(path).meshes[0].material.textures
    assert (textures.alpha_mode, textures.alpha_cutoff, textures.alpha_factor) == ("mask", 0.3, 0.8)
    untextured = json.loads(write_gltf(tmp_path / "u.gltf").read_text())  # no TEXCOORD_0, no texture: none needed
    untextured["materials"][0].update(alphaMode="MASK")
    untextured["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.3, 0.5, 0.7, 0.2]
    (tmp_path / "u.gltf").write_text(json.dumps(untextured))
    (item,) = load_gltf(tmp_path / "u.gltf").meshes
    assert item.material.textures.alpha_factor == 0.2 and np.all(item.mesh.uvs == 0.0)
    material["alphaMode"] = "SOMETIMES"
    path.write_text(json.dumps(doc))
    with pytest.raises(SceneError, match="unknown alphaMode 'SOMETIMES'"):
        load_gltf(path)


def test_a_textured_round_trip_through_trimesh(tmp_path):
    """trimesh writes a textured box (UVs, a base-colour PNG); lightprobe reads back the same texels and UVs."""
    trimesh = pytest.importorskip("trimesh")
    image_module = pytest.importorskip("PIL.Image")
    from trimesh.visual.material import PBRMaterial

    rng = np.random.default_rng(12)
    texels = rng.integers(0, 256, size=(6, 10, 3), dtype=np.uint8)
    box = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    uv = rng.random((box.vertices.shape[0], 2))
    material = PBRMaterial(baseColorTexture=image_module.fromarray(texels), metallicFactor=0.0, roughnessFactor=0.5)
    box.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    box.export(tmp_path / "box.glb")
    (item,) = load_gltf(tmp_path / "box.glb").meshes
    texture = item.material.textures.base_color
    np.testing.assert_array_equal(texture.pixels[:, :, :3], texels)
    # trimesh stores glTF's v = 1 - its own v (OpenGL's, up the image); lightprobe reads the file's
    ours = {
        tuple(np.round(v, 5)): tuple(np.round(t, 5)) for v, t in zip(item.mesh.vertices, item.mesh.uvs, strict=True)
    }
    for v, t in zip(box.vertices, uv, strict=True):
        assert ours[tuple(np.round(v, 5))] == pytest.approx((t[0], 1.0 - t[1]), abs=1e-5)
