"""A suite scene in Blender Cycles (``bpy``): the peer of benchmarks/suite.py where Cycles is the stronger one.

Two halves that run in different Pythons:

* :func:`export` (numpy only) runs in the suite's own Python: it flattens a renderer-neutral description of
  ``lightprobe.reference_scenes.describe`` into plain arrays and JSON (one ``.npz``): the surfaces grouped into
  one triangle mesh per (material, sidedness, shading), the spheres, the emitters as **one** triangle mesh with a
  radiance index per face (the city's 100,000 windows are 200,000 triangles of one object), the camera and the
  environment (a constant, or a lat-long image file written beside it).
* :func:`build` runs under a Python that has ``bpy`` (``pip install bpy==5.0.1``, Python 3.11; it cannot import
  lightprobe's package) and makes the Blender scene from that file; :func:`configure` sets Cycles up as the suite
  compares it.

Translation (as ``../shared/peers/cycles/render.py``, the measured recipe for the peer scene):

* The description is Y up, Blender Z up: every point and direction (x, y, z) becomes (x, -z, y), a rotation
  (windings and handedness kept).
* Camera: perspective, horizontal field of view (``sensor_fit`` HORIZONTAL), looking from ``origin`` at ``target``
  with up = +Y, as Mitsuba's ``look_at``.
* Lambertian: Diffuse BSDF, roughness 0.  Conductor: Metallic BSDF, GGX (not multiscatter), physical conductor
  Fresnel with the RGB eta and k, Blender roughness = sqrt(alpha).  A surface not ``two_sided`` is black seen from
  behind (a Mix Shader on Geometry > Backfacing with an empty shader), as Mitsuba's one-sided BSDFs.
* Emitters: Emission shader (strength 1: radiance = its colour) on the front (edge_u x edge_v, or the winding)
  and nothing behind (black, opaque, as Mitsuba's area emitters with a black BSDF), emission sampling FRONT.
  **One material per distinct radiance**: Cycles' light tree (and its light distribution without the tree)
  weights an emissive triangle by area x its shader's emission estimate, which is a constant only for a shader
  whose colour is a constant; a per-face colour attribute would leave every triangle the same weight.
* Sphere lights (the area and glossy scenes): Blender point lights of that radius, soft falloff off (a sphere of
  uniform radiance L: power 4 pi^2 r^2 L, Cycles' eval factor 1 / (4 pi * pi r^2)), plus a black exact sphere of
  radius 0.999 r that occludes as Mitsuba's emitting sphere does.
* Spheres: exact (a one-point point cloud, which Cycles intersects analytically).
* Environment: a constant is a Background colour; a lat-long map is looked up as Mitsuba does (the description's
  convention: u = atan2(d.x, -d.z) / (2 pi), texel-centred columns, corner-aligned rows) by math nodes and an
  Image Texture (linear), as the kit's ``--env-lookup mitsuba`` (its Environment Texture, ``lookup="envtex"``,
  puts rows half a texel off); world importance map 4096 x 2048 (the kit's finding: at the map's own
  resolution the cells beside a small sun miss it and BSDF rays that find it make fireflies).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

MAP_RESOLUTION = 4096  # the world importance map's width (manual), see the module docstring


# ------------------------------------------------------------------------------- export (the suite's Python)


class NotTranslated(ValueError):
    """A description holds something the Cycles translation does not make."""


def _quads(origins, edges_u, edges_v):
    """(vertices, faces) of rectangles as two triangles each, wound so that the normal is edge_u x edge_v."""
    o, u, v = (np.asarray(x, np.float64).reshape(-1, 3) for x in (origins, edges_u, edges_v))
    vertices = np.stack([o, o + u, o + u + v, o + v], axis=1).reshape(-1, 3)
    base = 4 * np.arange(o.shape[0])[:, None]
    return vertices, (base + np.array([0, 1, 2, 0, 2, 3])).reshape(-1, 3)


def flatten(desc: dict) -> tuple[dict, dict]:
    """(meta, arrays) of a description: meta is JSON (camera, environment, materials, the surface meshes' and
    spheres' materials, the sphere lights), arrays the meshes' vertices and faces (the description's Y-up
    coordinates).  Raises :class:`NotTranslated` for a shape it does not know (a glTF asset)."""
    meta = {"name": desc.get("name"), "camera": {k: np.asarray(v).tolist() for k, v in desc["camera"].items()},
            "environment": desc["environment"], "materials": desc["materials"], "surfaces": [], "spheres": [],
            "sphere_lights": []}  # fmt: skip
    arrays = {}
    groups: dict = {}  # (material, two_sided) -> [vertices], [faces] of flat-shaded pieces
    emit_v, emit_f, emit_radiance = [], [], []
    count = 0

    def add_emitter(vertices, faces, radiance):
        nonlocal count
        emit_v.append(np.asarray(vertices, np.float64))
        emit_f.append(np.asarray(faces, np.int64) + count)
        emit_radiance.append(np.broadcast_to(np.asarray(radiance, np.float64), (len(faces), 3)))
        count += len(vertices)

    for o in desc["objects"]:
        shape = o["shape"]
        if shape == "gltf":
            raise NotTranslated("a glTF asset (its textured metallic-roughness materials are not translated)")
        if shape == "rectangles":  # the city's windows: emitters
            levels = np.asarray(o["levels"], np.float64)
            v, f = _quads(o["origins"], o["edges_u"], o["edges_v"])
            add_emitter(v, f, np.repeat(levels[np.asarray(o["level"])], 2, axis=0))
            continue
        if "emission" in o:
            if o.get("two_sided"):
                raise NotTranslated("a two-sided emitter")
            if shape == "rectangle":
                add_emitter(*_quads(o["origin"], o["edge_u"], o["edge_v"]), o["emission"])
            elif shape == "sphere":
                meta["sphere_lights"].append({"center": np.asarray(o["center"], float).tolist(),
                                              "radius": float(o["radius"]),
                                              "radiance": np.broadcast_to(o["emission"], 3).tolist()})  # fmt: skip
            else:
                add_emitter(o["vertices"], o["faces"], o["emission"])
            continue
        key = (o["material"], bool(o.get("two_sided", False)))
        if shape == "sphere":
            meta["spheres"].append({"center": np.asarray(o["center"], float).tolist(), "radius": float(o["radius"]),
                                    "material": key[0], "two_sided": key[1]})  # fmt: skip
        elif shape == "rectangle":
            groups.setdefault(key, []).append(_quads(o["origin"], o["edge_u"], o["edge_v"]))
        elif shape == "triangles" and "normals" not in o:
            groups.setdefault(key, []).append((np.asarray(o["vertices"], float), np.asarray(o["faces"], np.int64)))
        elif shape == "triangles":  # smooth-shaded: its own mesh with its normals
            i = len(meta["surfaces"])
            meta["surfaces"].append({"material": key[0], "two_sided": key[1], "smooth": True})
            arrays[f"surface{i}_vertices"] = np.asarray(o["vertices"], np.float64)
            arrays[f"surface{i}_faces"] = np.asarray(o["faces"], np.int64)
            arrays[f"surface{i}_normals"] = np.asarray(o["normals"], np.float64)
        else:
            raise NotTranslated(f"shape {shape!r}")
    for (material, two_sided), pieces in groups.items():
        i = len(meta["surfaces"])
        meta["surfaces"].append({"material": material, "two_sided": two_sided, "smooth": False})
        offsets = np.cumsum([0] + [len(v) for v, _ in pieces])
        arrays[f"surface{i}_vertices"] = np.concatenate([v for v, _ in pieces])
        arrays[f"surface{i}_faces"] = np.concatenate([f + offsets[k] for k, (_, f) in enumerate(pieces)])
    if emit_v:
        radiance = np.concatenate(emit_radiance)
        levels, index = np.unique(radiance, axis=0, return_inverse=True)
        arrays["emitters_vertices"] = np.concatenate(emit_v)
        arrays["emitters_faces"] = np.concatenate(emit_f)
        arrays["emitters_level"] = index.reshape(-1).astype(np.int64)
        arrays["emitters_levels"] = levels
    return meta, arrays


def export(desc: dict, path: Path, *, resolution, env_file: str | None = None) -> dict:
    """Write the description as Cycles' input file ``path`` (.npz); ``env_file``: the environment image written as a
    file (a procedural sky); a ``constant`` environment stays a colour.  Returns the meta."""
    meta, arrays = flatten(desc)
    meta["resolution"] = [int(x) for x in resolution]
    env = desc["environment"]
    if env is None or "constant" in env:
        meta["environment"] = env
    elif "file" in env:
        meta["environment"] = {"file": str(env["file"])}
    else:
        if env_file is None:
            raise NotTranslated("a procedural environment without its image file")
        meta["environment"] = {"file": str(env_file)}
    np.savez(path, meta=np.array(json.dumps(meta)), **arrays)
    return meta


def load(path) -> tuple[dict, dict]:
    with np.load(path) as f:
        meta = json.loads(str(f["meta"]))
        arrays = {k: f[k] for k in f.files if k != "meta"}
    return meta, arrays


def to_blender(p) -> np.ndarray:
    """Y-up points or directions (..., 3) -> Blender's Z up: (x, y, z) -> (x, -z, y), a rotation."""
    p = np.asarray(p, np.float64)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def camera_matrix(origin, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Blender's camera-to-world (4 x 4, Z up) looking from ``origin`` at ``target`` (Y up): Blender cameras look
    along local -Z with +Y up and +X right."""
    o, t, u = (np.asarray(x, np.float64) for x in (origin, target, up))
    f = (t - o) / np.linalg.norm(t - o)
    r = np.cross(f, u)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    fb, rb, ub, ob = (to_blender(x) for x in (f, r, u, o))
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = rb, ub, -fb, ob
    return m


def sphere_light_power(radius: float, radiance) -> np.ndarray:
    """A Blender point light's power (W, per channel) for a sphere of ``radius`` and uniform ``radiance``: Cycles
    evaluates a point light of power P and radius r as radiance P / (4 pi * pi r^2)."""
    return 4.0 * math.pi**2 * radius**2 * np.asarray(radiance, np.float64)


# ---------------------------------------------------------------------------------- build (under bpy's Python)


def _material(name: str, spec: dict, two_sided: bool):
    import bpy

    m = bpy.data.materials.new(name)
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "ALL"
    if spec["model"] == "lambertian":
        b = nt.nodes.new("ShaderNodeBsdfDiffuse")
        b.inputs["Color"].default_value = (*np.broadcast_to(spec["reflectance"], 3), 1.0)
        b.inputs["Roughness"].default_value = 0.0  # Lambertian (else Oren-Nayar)
    elif spec["model"] == "rough_conductor":
        b = nt.nodes.new("ShaderNodeBsdfMetallic")
        b.distribution = "GGX"
        b.fresnel_type = "PHYSICAL_CONDUCTOR"
        b.inputs["IOR"].default_value = tuple(float(x) for x in spec["eta"])
        b.inputs["Extinction"].default_value = tuple(float(x) for x in spec["k"])
        b.inputs["Roughness"].default_value = math.sqrt(float(spec["alpha"]))
    else:
        raise NotTranslated(f"material model {spec['model']!r}")
    if two_sided:
        nt.links.new(b.outputs[0], out.inputs["Surface"])
    else:
        _front_only(nt, b.outputs[0], out)
    return m


def _front_only(nt, shader_output, out) -> None:
    """Surface = the shader on the front, nothing (black, opaque) behind."""
    geometry = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geometry.outputs["Backfacing"], mix.inputs[0])
    nt.links.new(shader_output, mix.inputs[1])  # factor 0: the front
    nt.links.new(mix.outputs[0], out.inputs["Surface"])


def _emission_material(name: str, radiance):
    import bpy

    m = bpy.data.materials.new(name)
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "ALL"
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (*(float(x) for x in radiance), 1.0)
    e.inputs["Strength"].default_value = 1.0
    _front_only(nt, e.outputs[0], out)
    m.cycles.emission_sampling = "FRONT"
    return m


def _black_material():
    import bpy

    m = bpy.data.materials.new("black")
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    b = nt.nodes.new("ShaderNodeBsdfDiffuse")
    b.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    nt.links.new(b.outputs[0], out.inputs["Surface"])
    return m


def _mesh(name: str, vertices, faces, materials, material_index=None, normals=None):
    """A Blender mesh object from arrays (Y up), built with foreach_set (fast for 200,000 triangles); flat-shaded
    unless ``normals`` (per vertex, then smooth with those normals)."""
    import bpy

    v = to_blender(vertices).astype(np.float32)
    f = np.asarray(faces, np.int32)
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(v))
    me.vertices.foreach_set("co", v.ravel())
    me.loops.add(3 * len(f))
    me.loops.foreach_set("vertex_index", f.ravel())
    me.polygons.add(len(f))
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * len(f), 3, dtype=np.int32))
    for m in materials:
        me.materials.append(m)
    if material_index is not None:
        me.polygons.foreach_set("material_index", np.asarray(material_index, np.int32))
    me.update(calc_edges=True)
    if normals is None:
        me.shade_flat()
    else:
        me.shade_smooth()
        n = to_blender(normals)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        me.normals_split_custom_set_from_vertices([tuple(x) for x in n])
    ob = bpy.data.objects.new(name, me)
    # Cycles moves shadow-ray origins of smooth triangles near the terminator by default; Mitsuba does not
    ob.shadow_terminator_geometry_offset = 0.0
    ob.shadow_terminator_normal_offset = 0.0
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _sphere(name: str, center, radius: float, material):
    """An exact sphere: a one-point point cloud (geometry nodes Mesh to Points), intersected analytically."""
    import bpy

    me = bpy.data.meshes.new(name + "_point")
    me.from_pydata([tuple(to_blender(center))], [], [])
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    ng = bpy.data.node_groups.new(name + "_points", "GeometryNodeTree")
    ng.interface.new_socket(name="Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket(name="Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi, go = ng.nodes.new("NodeGroupInput"), ng.nodes.new("NodeGroupOutput")
    points = ng.nodes.new("GeometryNodeMeshToPoints")
    points.mode = "VERTICES"
    points.inputs["Radius"].default_value = float(radius)
    setm = ng.nodes.new("GeometryNodeSetMaterial")
    setm.inputs["Material"].default_value = material
    ng.links.new(gi.outputs[0], points.inputs["Mesh"])
    ng.links.new(points.outputs["Points"], setm.inputs["Geometry"])
    ng.links.new(setm.outputs["Geometry"], go.inputs[0])
    ob.modifiers.new("points", "NODES").node_group = ng
    return ob


def _sphere_light(name: str, center, radius: float, radiance):
    import bpy

    power = sphere_light_power(radius, radiance)
    scale = float(power.max())
    light = bpy.data.lights.new(name, "POINT")
    light.energy = scale
    light.color = tuple(float(x) for x in power / scale)
    light.shadow_soft_size = float(radius)
    light.use_soft_falloff = False  # a sphere of uniform radiance (Blender 4+), not the legacy soft point light
    ob = bpy.data.objects.new(name, light)
    ob.location = tuple(to_blender(center))
    # a light object is hidden from camera rays by default; Mitsuba's emitting sphere is seen
    ob.visible_camera = ob.visible_diffuse = ob.visible_glossy = True
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _world(env, map_resolution: int, lookup: str = "mitsuba"):
    import bpy

    world = bpy.data.worlds.new("world")
    bpy.context.scene.world = world
    nt = world.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputWorld")
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 1.0
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    if env is None:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        return world
    if "constant" in env:
        bg.inputs["Color"].default_value = (*(float(x) for x in np.broadcast_to(env["constant"], 3)), 1.0)
        return world
    img = bpy.data.images.load(str(env["file"]), check_existing=False)
    img.colorspace_settings.name = "Linear Rec.709"
    coords = nt.nodes.new("ShaderNodeTexCoord")
    if lookup == "envtex":  # Cycles' own lookup: rows texel-centred, half a texel off Mitsuba's in elevation
        tex = nt.nodes.new("ShaderNodeTexEnvironment")
        tex.image = img
        tex.projection = "EQUIRECTANGULAR"
        tex.interpolation = "Linear"
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.vector_type = "POINT"
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(90.0))
        nt.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    else:
        # Mitsuba's lookup (the description's): D = the direction in Blender's frame, the description's
        # d = (D.x, D.z, -D.y); u = atan2(d.x, -d.z) / (2 pi) = atan2(D.x, D.y) / (2 pi) (periodic: REPEAT; Mitsuba's
        # columns are texel-centred, as an Image Texture's), v = acos(D.z) / pi with Mitsuba's rows corner-aligned
        # (row coordinate v (H - 1)) where an Image Texture's are texel-centred (V' H - 0.5): V' = (v (H-1) + 0.5) / H,
        # and Blender's image V runs bottom-up: V = 1 - V' (../shared/peers/cycles/render.py --env-lookup mitsuba)
        H = img.size[1]

        def op(name, a, b=None, c=None):
            n = nt.nodes.new("ShaderNodeMath")
            n.operation = name
            for k, v in enumerate((a, b, c)):
                if v is None:
                    continue
                if isinstance(v, (int, float)):
                    n.inputs[k].default_value = float(v)
                else:
                    nt.links.new(v, n.inputs[k])
            return n.outputs[0]

        unit = nt.nodes.new("ShaderNodeVectorMath")
        unit.operation = "NORMALIZE"
        nt.links.new(coords.outputs["Generated"], unit.inputs[0])
        xyz = nt.nodes.new("ShaderNodeSeparateXYZ")
        nt.links.new(unit.outputs["Vector"], xyz.inputs[0])
        u = op("MULTIPLY", op("ARCTAN2", xyz.outputs["X"], xyz.outputs["Y"]), 1.0 / (2.0 * math.pi))
        v = op("MULTIPLY_ADD", op("ARCCOSINE", xyz.outputs["Z"]), -(H - 1) / (math.pi * H), 1.0 - 0.5 / H)
        uv = nt.nodes.new("ShaderNodeCombineXYZ")
        nt.links.new(u, uv.inputs["X"])
        nt.links.new(v, uv.inputs["Y"])
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = img
        tex.interpolation = "Linear"
        tex.extension = "REPEAT"
        tex.projection = "FLAT"
        nt.links.new(uv.outputs["Vector"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    world.cycles.sampling_method = "MANUAL"
    world.cycles.sample_map_resolution = int(map_resolution)
    return world


def build(path, *, map_resolution: int = MAP_RESOLUTION, lookup: str = "mitsuba") -> dict:
    """The Blender scene of an exported description (a fresh, empty file first).  ``lookup``: a lat-long map's,
    "mitsuba" (the description's convention) or "envtex" (Cycles' Environment Texture).  Returns its counts."""
    import bpy
    from mathutils import Matrix

    meta, arrays = load(path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    materials: dict = {}

    def material(name: str, two_sided: bool):
        key = (name, two_sided)
        if key not in materials:
            materials[key] = _material(f"{name}{'_2s' if two_sided else ''}", meta["materials"][name], two_sided)
        return materials[key]

    for i, s in enumerate(meta["surfaces"]):
        _mesh(f"surface{i}", arrays[f"surface{i}_vertices"], arrays[f"surface{i}_faces"],
              [material(s["material"], s["two_sided"])], normals=arrays.get(f"surface{i}_normals"))  # fmt: skip
    for i, s in enumerate(meta["spheres"]):
        _sphere(f"sphere{i}", s["center"], s["radius"], material(s["material"], s["two_sided"]))
    lights = 0
    if "emitters_vertices" in arrays:
        levels = arrays["emitters_levels"]
        emissive = [_emission_material(f"emitter{k}", radiance) for k, radiance in enumerate(levels)]
        _mesh("emitters", arrays["emitters_vertices"], arrays["emitters_faces"], emissive, arrays["emitters_level"])
        lights += len(arrays["emitters_faces"])
    black = None
    for i, s in enumerate(meta["sphere_lights"]):
        _sphere_light(f"sphere_light{i}", s["center"], s["radius"], s["radiance"])
        black = black or _black_material()
        _sphere(f"sphere_light{i}_occluder", s["center"], 0.999 * s["radius"], black)
        lights += 1

    cam = meta["camera"]
    data = bpy.data.cameras.new("camera")
    data.type = "PERSP"
    data.sensor_fit = "HORIZONTAL"  # the description's fov is horizontal (Mitsuba's fov_axis "x")
    data.lens_unit = "FOV"
    data.angle = math.radians(float(cam["fov"]))
    data.clip_start, data.clip_end = 1e-3, 1e5
    ob = bpy.data.objects.new("camera", data)
    ob.matrix_world = Matrix(camera_matrix(cam["origin"], cam["target"]).tolist())
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.scene.camera = ob
    _world(meta["environment"], map_resolution, lookup)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = meta["resolution"]
    return {"lights": lights, "materials": len(bpy.data.materials), "objects": len(bpy.data.objects)}


def configure(*, spp: int, seed: int, light_tree: bool, threads: int = 2) -> None:
    """Cycles as the suite compares it: CPU, direct light only (max_bounces 0: one light sample and one BSDF sample
    per camera sample, combined by MIS), box filter 1 px, no denoising, adaptive sampling, clamping, path guiding
    or light threshold, a fixed seed, ``threads`` threads."""
    import bpy

    scene = bpy.context.scene
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_percentage = 100
    r.film_transparent = False
    r.use_motion_blur = False
    r.threads_mode = "FIXED"
    r.threads = threads
    r.use_persistent_data = False  # a final render: every render syncs afresh, with a static BVH
    r.use_compositing = False
    r.use_sequencer = False
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    c = scene.cycles
    c.device = "CPU"
    c.samples = spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.use_preview_denoising = False
    c.use_guiding = False
    c.max_bounces = 0
    c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
    c.min_light_bounces = 0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.light_sampling_threshold = 0.0
    c.use_light_tree = light_tree
    c.direct_light_sampling_type = "MULTIPLE_IMPORTANCE_SAMPLING"
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.seed = seed
    c.use_animated_seed = False
    c.sampling_pattern = "AUTOMATIC"
    c.film_exposure = 1.0
    c.use_auto_tile = True


class StatsClock:
    """Timestamps Cycles' status lines (``bpy.app.handlers.render_stats``)."""

    def __init__(self):
        self.events = []

    def __call__(self, *args):
        import time

        self.events.append((time.perf_counter(), args[0] if args and isinstance(args[0], str) else str(args)))

    def first(self, pred):
        return next((t for t, s in self.events if pred(s)), None)


def render(clock: StatsClock, tmpdir: str) -> tuple[np.ndarray, dict]:
    """One render: the image (H, W, 3) float64, row 0 at the top, and its times: ``sync_s`` from the call to
    Cycles' first "Sample" status line (scene sync, BVH and light tree build, importance map), ``trace_s`` from
    there to "Finished" (path tracing), ``wall_s`` the whole call, ``cpu_s`` the process's CPU seconds."""
    import os
    import resource
    import time

    import bpy

    clock.events.clear()
    ru0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    bpy.ops.render.render(write_still=False)
    t1, ru1 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
    ts = clock.first(lambda s: "Sample " in s)
    te = clock.first(lambda s: s.rstrip().endswith("Finished"))
    times = {"wall_s": t1 - t0, "sync_s": None if ts is None else ts - t0,
             "trace_s": None if ts is None else (te if te is not None else t1) - ts,
             "cpu_s": (ru1.ru_utime + ru1.ru_stime) - (ru0.ru_utime + ru0.ru_stime)}  # fmt: skip
    path = os.path.join(tmpdir, "result.exr")
    bpy.data.images["Render Result"].save_render(path)
    img = bpy.data.images.load(path, check_existing=False)
    w, h = img.size
    buf = np.empty(w * h * img.channels, np.float32)
    img.pixels.foreach_get(buf)
    bpy.data.images.remove(img)
    return buf.reshape(h, w, -1)[::-1, :, :3].astype(np.float64), times
