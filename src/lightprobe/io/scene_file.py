"""The scene file format (TOML).  Relative paths are relative to the scene file.

Example (every key shown; optional ones have their default)::

    [camera]
    origin = [0.0, 2.6, 6.8]
    target = [0.0, 0.7, 0.0]
    up = [0.0, 1.0, 0.0]                # optional
    fov = 40.0                          # degrees, along fov_axis
    fov_axis = "y"                      # optional: "y" vertical (default) or "x" horizontal
    resolution = [512, 512]

    [environment]                       # exactly one of file / sky / constant, or type = "sunsky" (below);
                                        #   optional when objects emit
    file = "sky.exr"                    # .exr, .hdr, .pfm
    mapping = "latlong"                 # or "angular" (Debevec light probe)
    scale = 1.0
    rotation = 0.0                      # degrees about +Y
    lookup = "bilinear"                 # or "nearest"
    pdf = "bilinear"                    # or "exact", "pbrt" (default: bilinear for bilinear lookups, else exact)
    # pdf_weights = "bilinear"          # with pdf = "exact" or "pbrt" only: or "texel", "blur"
    # sky = { sun_elevation = 35, sun_azimuth = 45, sun_diameter = 0.5, sun_radiance = [4e4, 3.8e4, 3.4e4],
    #         width = 1024, height = 512 }     # the procedural sky with a sun
    # constant = [1.0, 1.0, 1.0]              # a uniform white furnace

    # [environment]                     # or: the Hosek-Wilkie sun and sky (Mitsuba 3.9.1's sunsky)
    # type = "sunsky"                   #   radiance in W m^-2 sr^-1 nm^-1 times Mitsuba's RGB normalisation
    # turbidity = 3.0                   #   1 (clear, arctic) to 10 (hazy)
    # albedo = 0.3                      #   the ground's, 0-1: a number or [r, g, b]
    # sun_elevation = 45.0              #   degrees above the horizon, 0-90 (Mitsuba's sky is black below it)
    # sun_azimuth = 0.0                 #   degrees, as the sky's u = azimuth / 360 (0: toward -Z, 90: toward +X)
    # sun_direction = [0.3, 1.0, -0.2]  #   or the world direction toward the sun (not with sun_elevation)
    # year = 2010                       #   or where the sun stands at a date, time and place (Mitsuba's: noon
    # month = 7                         #   sun toward +X in the north, morning sun +Z); any of these keys, the
    # day = 10                          #   others Mitsuba's defaults (Tokyo, 10 July 2010, 15:00)
    # hour = 15.0                       #   local time: hour, minute, second
    # latitude = 35.6894                #   degrees, north positive; longitude east positive
    # longitude = 139.6917
    # timezone = 9.0                    #   hours from UTC
    # sun_scale = 1.0                   #   multiplies the sun (0: no sun)
    # sky_scale = 1.0                   #   multiplies the sky (0: no sky)
    # sun_aperture = 0.5358             #   the sun's angular diameter in degrees (its irradiance is kept)
    # limb_darkening = true             #   Mitsuba's complex_sun; false: its default disc of uniform radiance
    # width = 1024                      #   the sky's lat-long map: width x (width / 2 + 1)

    [materials.floor]
    type = "lambert"                    # lambert: albedo
    albedo = 0.5
    [materials.red]
    type = "plastic"                    # plastic: diffuse, alpha, eta
    diffuse = [0.6, 0.15, 0.1]
    alpha = 0.3
    [materials.gold]
    type = "conductor"                  # conductor: alpha, material ("Al", "Au", "none") or eta + k, fresnel
    alpha = 0.3
    material = "Au"
    [materials.shiny]
    type = "phong"                      # phong: rho_d, rho_s, exponent, estimator
    rho_d = 0.2
    rho_s = 0.7
    exponent = 200
    [materials.painted]
    type = "metallic_roughness"         # glTF 2.0's: base_color, metallic, roughness (defaults 1, 1, 1)
    base_color = [0.8, 0.1, 0.1]
    metallic = 0.0
    roughness = 0.4
    # lambert and metallic_roughness take textures on meshes with UVs (files relative to this one; glTF's meaning):
    # base_color_texture = "albedo.png"            # sRGB, multiplies base_color / albedo
    # metallic_roughness_texture = "mr.png"        # G roughness, B metallic (metallic_roughness only)
    # normal_texture = "normal.png"                # tangent space, +Y up; normal_scale = 1.0
    # texture_wrap = "repeat"                      # or "mirrored_repeat", "clamp"; texture_filter = "linear"
    # alpha_mode = "mask"                          # cut out where the base colour's alpha < alpha_cutoff (0.5)

    [[objects]]
    type = "mesh"                       # OBJ, PLY, PLY.GZ, glTF/GLB
    file = "bunny.obj"
    material = "red"
    transform = { scale = 5.0, rotate = [0, 1, 0, 30], translate = [0, 0, 0] }   # or { matrix = [[...]] }
    smooth = true                       # interpolate vertex normals (computed if the file has none)
    two_sided = false                   # shade back faces as front faces

    [[objects]]
    type = "sphere"
    center = [1.7, 0.55, 0.9]
    radius = 0.55
    material = "gold"

    [[objects]]
    type = "ground"                     # the plane y = height, a square of side size
    height = 0.0
    size = 100.0
    material = "floor"

    [[objects]]
    type = "rectangle"                  # corner origin, edges edge_u and edge_v; normal = edge_u x edge_v
    origin = [-1, 0, -1]
    edge_u = [0, 0, 2]
    edge_v = [2, 0, 0]
    material = "floor"

    [[objects]]                         # a mesh with one radiance per face: an (F,) or (F, 3) .npy array, or
    type = "mesh"                       #   "colors" (the file's face colours, 8-bit / 255), times emission_scale
    file = "panels.ply"
    face_emission = "panels.npy"
    emission_scale = 10.0

    [[objects]]                         # any object can emit: an area light (a mesh: one light per triangle)
    type = "rectangle"
    origin = [-0.5, 3, -0.5]
    edge_u = [1, 0, 0]                  # edge_u x edge_v = -Y: it emits downward (one-sided unless two_sided)
    edge_v = [0, 0, 1]
    emission = [1.0, 0.9, 0.8]          # radiance, RGB or a number; `material` is optional for emitters
    emission_scale = 20.0

    [[lights]]                          # a point light: intensity in W/sr (RGB or a number), in every direction
    type = "point"
    position = [2.0, 3.0, 1.0]
    intensity = 40.0
    intensity_scale = 1.0               # optional, multiplies intensity

    [[lights]]                          # a directional light (a sun): irradiance E in W/m^2 at normal incidence
    type = "directional"                #   (RGB or a number) from a disc of angular diameter `angle` degrees
    direction = [-0.3, -1.0, 0.2]       #   (0: a delta light); `direction` is the way its light travels
    irradiance = [3.0, 2.8, 2.5]
    angle = 0.53
    irradiance_scale = 1.0              # optional, multiplies irradiance

    [[lights]]                          # a spot light: full intensity within falloff_start degrees of its axis,
    type = "spot"                       #   none beyond cone_angle (default falloff_start: cone_angle - 5)
    position = [0.0, 4.0, 2.0]
    target = [0.0, 0.0, 0.0]
    intensity = [60.0, 55.0, 50.0]
    cone_angle = 25.0
    falloff_start = 20.0

    [render]                            # optional defaults for `lightprobe render` (options override them)
    spp = 64
    strategy = "mis"
    heuristic = "balance"               # default: balance with an environment map alone, else power
    bsdf_samples = 8                    # default: 8 with an environment map alone, 2 with one beside other
                                        # lights, else 1
    env_samples = 8                     # per chosen light (N); default: 8 with an environment map alone, else 1
    seed = 0
    sampler = "sobol"                   # sobol (Owen-scrambled Sobol') | independent
    env_candidates = 1                  # > 1: resampled environment samples (RIS) from this many candidates
    light_sampler = "learned"           # uniform | power | bvh | learned (a BVH that learns)
    lights_per_sample = 2               # lights chosen per camera sample (K); default: 1 with an environment map
                                        # or one delta light alone, 4 with 64 bounded lights or more
                                        # (4, 8 or 16 by a probe in long renders), else 2
    light_strategy = "solid-angle"      # area | solid-angle | hemisphere | cosine

Every mistake is a :class:`~lightprobe.errors.SceneError` naming the file and the table at fault.
"""

from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path

import numpy as np

from ..bsdfs import GGXConductor, Lambert, MetallicRoughness, Phong, RoughPlastic
from ..emitters.directional import DirectionalLight
from ..emitters.envmap import EnvironmentMap
from ..emitters.procedural import constant, sky_with_sun
from ..emitters.punctual import PointLight, SpotLight
from ..emitters.sunsky import SunSky
from ..errors import LightprobeError, SceneError, numeric_array
from ..geometry.camera import Camera
from ..geometry.mesh import TriangleMesh
from ..geometry.shapes import Rectangle, Sphere
from ..integrators.settings import read_render_table
from ..scene import Scene

__all__ = ["load_scene", "material_from_table"]


class _Table:
    """A TOML table with checked access: unknown keys and wrong types are errors naming where they are."""

    def __init__(self, data, where: str):
        if not isinstance(data, dict):
            raise SceneError(f"{where}: expected a table, got {type(data).__name__}")
        self.data = data
        self.where = where
        self.used: set[str] = set()

    def get(self, key, default=None, *, required: bool = False):
        self.used.add(key)
        if key not in self.data:
            if required:
                raise SceneError(f"{self.where}: missing required key {key!r}")
            return default
        return self.data[key]

    def number(self, key, default=None, *, required: bool = False):
        value = self.get(key, default, required=required)
        if value is not None and (
            isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value)
        ):
            raise SceneError(f"{self.where}: {key} must be a finite number, got {value!r}")
        return value

    def integer(self, key, default=None, *, minimum: int | None = None):
        value = self.get(key, default)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            raise SceneError(f"{self.where}: {key} must be an integer, got {value!r}")
        if value is not None and minimum is not None and value < minimum:
            raise SceneError(f"{self.where}: {key} must be >= {minimum}, got {value!r}")
        return value

    def choice(self, key, choices, default=None):
        value = self.string(key, default)
        if value is not None and value not in choices:
            raise SceneError(f"{self.where}: {key} must be one of {', '.join(map(repr, choices))}, got {value!r}")
        return value

    def rgb(self, key, default=None):
        """A finite, non-negative number or [r, g, b]."""
        value = self.get(key, default)
        if value is None:
            return None
        arr = numeric_array(value, f"{self.where}: {key}", SceneError).reshape(-1)
        if arr.size not in (1, 3) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise SceneError(f"{self.where}: {key} must be a number >= 0 or [r, g, b] of them, got {value!r}")
        return np.repeat(arr, 3) if arr.size == 1 else arr

    def string(self, key, default=None, *, required: bool = False):
        value = self.get(key, default, required=required)
        if value is not None and not isinstance(value, str):
            raise SceneError(f"{self.where}: {key} must be a string, got {value!r}")
        return value

    def boolean(self, key, default=False):
        value = self.get(key, default)
        if not isinstance(value, bool):
            raise SceneError(f"{self.where}: {key} must be true or false, got {value!r}")
        return value

    def done(self) -> None:
        unknown = set(self.data) - self.used
        if unknown:
            raise SceneError(f"{self.where}: unknown key(s) {', '.join(sorted(unknown))}")


def _path(base: Path, value: str, where: str) -> Path:
    if not isinstance(value, str) or not value:
        raise SceneError(f"{where}: file must be a non-empty string")
    p = Path(value).expanduser()
    return p if p.is_absolute() else base / p


def _camera(t: _Table) -> Camera:
    cam = Camera(
        t.get("origin", required=True),
        t.get("target", required=True),
        t.get("up", (0.0, 1.0, 0.0)),
        fov=t.number("fov", 40.0),
        fov_axis=t.string("fov_axis", "y"),
        resolution=t.get("resolution", (512, 512)),
    )
    t.done()
    return cam


_SUNSKY_NUMBERS = ("turbidity", "sun_elevation", "sun_azimuth", "sun_scale", "sky_scale", "sun_aperture")
_SUNSKY_WHEN = ("hour", "minute", "second", "latitude", "longitude", "timezone")


def _sunsky(t: _Table) -> SunSky:
    """``[environment] type = "sunsky"``: the Hosek-Wilkie sun and sky (emitters/sunsky.py; its model
    emitters/hosek_wilkie.py)."""
    options = {key: t.number(key) for key in _SUNSKY_NUMBERS if key in t.data}
    if "albedo" in t.data:
        options["albedo"] = t.rgb("albedo")
    if "sun_direction" in t.data:
        options["sun_direction"] = numeric_array(t.get("sun_direction"), f"{t.where}: sun_direction", SceneError)
    if "width" in t.data:
        options["width"] = t.integer("width", minimum=8)
    if "limb_darkening" in t.data:
        options["limb_darkening"] = t.boolean("limb_darkening")
    when = {key: t.integer(key) for key in ("year", "month", "day") if key in t.data}
    when |= {key: t.number(key) for key in _SUNSKY_WHEN if key in t.data}
    if when:
        options["when"] = when
    t.done()
    return SunSky(**options)


def _environment(t: _Table, base: Path) -> EnvironmentMap | SunSky:
    """The ``[environment]`` table: a map, or a :class:`~lightprobe.emitters.sunsky.SunSky` (its sky a map, its sun
    a light) for ``type = "sunsky"``."""
    kind = t.string("type")
    if kind is not None:
        if kind != "sunsky":
            raise SceneError(f"{t.where}: type must be 'sunsky' (or leave it out for a map), got {kind!r}")
        return _sunsky(t)
    sources = [k for k in ("file", "sky", "constant") if k in t.data]
    if len(sources) != 1:
        raise SceneError(f"{t.where}: give exactly one of file, sky or constant (got {sources or 'none'})")
    options = {
        "scale": t.number("scale", 1.0),
        "rotation": t.number("rotation", 0.0),
        "lookup": t.string("lookup", "bilinear"),
    }
    if "pdf" in t.data:
        options["pdf"] = t.string("pdf")
    if "pdf_weights" in t.data:
        options["pdf_weights"] = t.string("pdf_weights")
    mapping = t.string("mapping", "latlong")
    if sources[0] == "file":
        env = EnvironmentMap.load(_path(base, t.get("file"), t.where), mapping=mapping, **options)
    elif sources[0] == "sky":
        sky = _Table(t.get("sky"), f"{t.where}.sky")
        diameter = sky.number("sun_diameter", 0.5)
        if not 0.0 < diameter < 90.0:
            raise SceneError(f"{sky.where}: sun_diameter must be in (0, 90) degrees, got {diameter!r}")
        image = sky_with_sun(
            sky.integer("width", 1024, minimum=2),
            sky.integer("height", 512, minimum=1),
            sun_elevation_deg=sky.number("sun_elevation", 35.0),
            sun_azimuth_deg=sky.number("sun_azimuth", 45.0),
            sun_diameter_deg=diameter,
            sun_radiance=sky.rgb("sun_radiance", (40000.0, 38000.0, 34000.0)),
        )
        sky.done()
        env = EnvironmentMap.from_array(image, source="procedural sky", **options)
    else:
        env = EnvironmentMap.from_array(constant(t.rgb("constant")), source="constant", **options)
    t.done()
    return env


_TEXTURE_KEYS = {"base_color_texture": "base_color", "metallic_roughness_texture": "metallic_roughness",
                 "normal_texture": "normal"}  # fmt: skip


def _textures(t: _Table, base: Path | None):
    """The material's ``*_texture`` files (relative to the scene file), ``normal_scale``, ``texture_wrap``,
    ``texture_filter``, ``alpha_mode``, ``alpha_cutoff``: a MaterialTextures, or None without any."""
    from ..textures import ImageTexture, MaterialTextures

    keys = set(_TEXTURE_KEYS) | {"normal_scale", "texture_wrap", "texture_filter", "alpha_mode", "alpha_cutoff"}
    if not keys & set(t.data):
        return None
    wrap = t.choice("texture_wrap", ("repeat", "mirrored_repeat", "clamp"), "repeat")
    filter_ = t.choice("texture_filter", ("linear", "nearest"), "linear")
    uses = {}
    for key, use in _TEXTURE_KEYS.items():
        value = t.string(key)
        if value is not None:
            if base is None:
                raise SceneError(f"{t.where}: {key}: textures are read from scene files only")
            uses[use] = ImageTexture.read(_path(base, value, t.where), wrap=wrap, filter=filter_)
    try:
        return MaterialTextures(
            **uses,
            normal_scale=t.number("normal_scale", 1.0),
            alpha_mode=t.choice("alpha_mode", ("opaque", "mask"), "opaque"),
            alpha_cutoff=t.number("alpha_cutoff", 0.5),
        )
    except LightprobeError as exc:
        raise SceneError(f"{t.where}: {exc}") from None


def _material(t: _Table, base: Path | None = None):
    kind = t.string("type", required=True)
    textures = _textures(t, base)
    if textures is not None and kind not in ("lambert", "metallic_roughness"):
        raise SceneError(f"{t.where}: textures are taken by lambert and metallic_roughness materials, not {kind}")
    if kind == "lambert":
        bsdf = Lambert(t.get("albedo", 0.5), textures=textures)
    elif kind == "phong":
        bsdf = Phong(
            t.get("rho_d", 0.5),
            t.get("rho_s", 0.5),
            t.number("exponent", 20.0),
            estimator=t.string("estimator", "mixture"),
        )
    elif kind == "conductor":
        bsdf = GGXConductor(
            t.number("alpha", 0.1),
            eta=t.get("eta"),
            k=t.get("k"),
            material=t.string("material"),
            specular_reflectance=t.get("specular_reflectance", 1.0),
            fresnel=t.boolean("fresnel", True),
        )
    elif kind == "plastic":
        bsdf = RoughPlastic(t.get("diffuse", 0.5), t.number("alpha", 0.1), eta=t.number("eta", 1.49 / 1.000277))
    elif kind == "metallic_roughness":
        bsdf = MetallicRoughness(
            t.get("base_color", 1.0), t.number("metallic", 1.0), t.number("roughness", 1.0), textures=textures
        )
    else:
        raise SceneError(
            f"{t.where}: unknown material type {kind!r}; use lambert, phong, conductor, plastic or metallic_roughness"
        )
    t.done()
    return bsdf


def material_from_table(data: dict, where: str):
    """A material from a ``[materials.NAME]`` table's keys (``type`` and its parameters); errors name ``where``."""
    return _within(where, lambda w: _material(_Table(data, w)))


def _face_emission(t: _Table, base: Path):
    """A mesh's ``face_emission``: None, ``"colors"`` (the file's face colours) or an (F,) / (F, 3) array from a
    ``.npy`` file, one row per face of the mesh file."""
    value = t.get("face_emission")
    if value is None:
        return None
    if "emission" in t.data:
        raise SceneError(f"{t.where}: give emission or face_emission, not both")
    if value == "colors":
        return value
    if not isinstance(value, str) or not value.endswith(".npy"):
        raise SceneError(f'{t.where}: face_emission must be "colors" or a .npy file, got {value!r}')
    path = _path(base, value, t.where)
    try:
        with open(path, "rb") as fh:
            head = fh.read(6)
        # numpy takes a file without the .npy magic for a pickle (or an .npz archive) and says so, which misleads
        if head != b"\x93NUMPY":
            size = path.stat().st_size
            raise SceneError(f"{path}: not a .npy array ({size} bytes of something else)" if size else
                             f"{path}: not a .npy array (the file is empty)")  # fmt: skip
        array = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise SceneError(f"{path}: no such file") from None
    except (OSError, EOFError, ValueError) as exc:
        raise SceneError(f"{path}: not a readable .npy array ({exc})") from None
    if array.dtype.kind not in "iuf" or array.ndim not in (1, 2) or (array.ndim == 2 and array.shape[1] != 3):
        raise SceneError(f"{path}: face_emission must be (F,) or (F, 3) numbers, got {array.dtype} {array.shape}")
    return array


def _object(scene: Scene, t: _Table, base: Path) -> None:
    kind = t.string("type", required=True)
    emission = t.rgb("emission")
    if emission is not None:
        emission = emission * t.number("emission_scale", 1.0)
    material = t.string("material", required=kind != "gltf" and emission is None and "face_emission" not in t.data)
    two_sided = t.boolean("two_sided", False)
    name = t.string("name", t.where)
    extra = {"emission": emission} if emission is not None else {}
    if kind == "gltf":
        from .gltf import load_gltf

        file = _path(base, t.get("file", required=True), t.where)
        transform = t.get("transform")
        if transform is not None and not isinstance(transform, dict):
            raise SceneError(f"{t.where}: transform must be a table")
        if "material" in t.data or emission is not None:
            raise SceneError(f"{t.where}: a glTF object takes its materials and emission from its file")
        t.done()
        asset = load_gltf(file, transform=transform)
        asset.add_to(scene, name=name if "name" in t.data else file.name)
        scene.cameras.update(dict.fromkeys(asset.cameras, asset))
        return
    if kind == "mesh":
        file = _path(base, t.get("file", required=True), t.where)
        face_values = _face_emission(t, base)
        mesh = TriangleMesh.load(file, smooth=t.boolean("smooth", True), face_values=face_values)
        if face_values is not None:
            radiance = mesh.face_values
            if radiance.shape[1] == 1:
                radiance = np.repeat(radiance, 3, axis=1)
            if radiance.shape[1] != 3 or not np.all(np.isfinite(radiance)) or np.any(radiance < 0):
                raise SceneError(f"{t.where}: face_emission must give each face a number >= 0 or [r, g, b] of them")
            extra = {"emission": radiance * t.number("emission_scale", 1.0)}
        transform = t.get("transform")
        if transform is not None and not isinstance(transform, dict):
            raise SceneError(f"{t.where}: transform must be a table")
        t.done()
        scene.add(mesh, material, transform=transform, two_sided=two_sided, name=name, **extra)
        return
    if kind == "sphere":
        shape = Sphere(t.get("center", required=True), t.number("radius", required=True))
    elif kind == "ground":
        shape = Rectangle.ground(height=t.number("height", 0.0), size=t.number("size", 100.0))
    elif kind == "rectangle":
        shape = Rectangle(
            t.get("origin", required=True), t.get("edge_u", required=True), t.get("edge_v", required=True)
        )
    else:
        raise SceneError(f"{t.where}: unknown object type {kind!r}; use mesh, sphere, ground or rectangle")
    t.done()
    scene.add(shape, material, two_sided=two_sided, name=name, **extra)


def _light(scene: Scene, t: _Table) -> None:
    kind = t.string("type", required=True)
    if kind not in ("point", "spot", "directional"):
        raise SceneError(
            f"{t.where}: unknown light type {kind!r}; use point, spot or directional (area lights are objects)"
        )
    if kind == "directional":
        direction = t.get("direction", required=True)
        t.get("irradiance", required=True)
        scale = t.number("irradiance_scale", 1.0)
        if scale < 0:
            raise SceneError(f"{t.where}: irradiance_scale must be >= 0, got {scale!r}")
        light = DirectionalLight(direction, t.rgb("irradiance") * scale, angle=t.number("angle", 0.0))
        t.done()
        scene.add_light(light)
        return
    position = t.get("position", required=True)
    t.get("intensity", required=True)
    scale = t.number("intensity_scale", 1.0)
    if scale < 0:
        raise SceneError(f"{t.where}: intensity_scale must be >= 0, got {scale!r}")
    intensity = t.rgb("intensity") * scale
    if kind == "point":
        light = PointLight(position, intensity)
    else:
        light = SpotLight(
            position,
            t.get("target", required=True),
            intensity,
            cone_angle=t.number("cone_angle", 30.0),
            falloff_start=t.number("falloff_start"),
        )
    t.done()
    scene.add_light(light)


def load_scene(path: str | os.PathLike, *, require_light: bool = True) -> tuple[Scene, dict]:
    """Read a scene file: returns the scene and its ``[render]`` defaults (possibly empty).  ``require_light=False``
    accepts a scene without lights (the caller adds some: ``lightprobe render --light``)."""
    p = Path(path)
    if not p.exists():
        raise SceneError(f"{p}: no such file")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SceneError(f"{p}: not valid TOML ({exc})") from None
    except OSError as exc:
        raise SceneError(f"{p}: cannot read ({exc.strerror})") from None
    base = p.resolve().parent
    root = _Table(data, str(p))
    camera = _within(f"{p}: [camera]", lambda w: _camera(_Table(root.get("camera", required=True), w)))
    env = None
    if "environment" in root.data:
        env = _within(f"{p}: [environment]", lambda w: _environment(_Table(root.get("environment"), w), base))
    sunsky = env if isinstance(env, SunSky) else None
    if sunsky is not None:
        env = _within(f"{p}: [environment]", lambda w: sunsky.environment())
    scene = Scene(camera, env, name=p.stem)
    if sunsky is not None and (sun := sunsky.sun()) is not None:
        scene.add_light(sun)
    materials = root.get("materials", {})
    if not isinstance(materials, dict):
        raise SceneError(f"{p}: [materials] must be a table of tables")
    for name, spec in materials.items():
        where = f"{p}: [materials.{name}]"
        scene.add_material(name, _within(where, lambda w, spec=spec: _material(_Table(spec, w), base)))
    objects = root.get("objects", [])
    if not isinstance(objects, list) or not objects:
        raise SceneError(f"{p}: the scene needs at least one [[objects]] entry")
    for i, spec in enumerate(objects):
        _within(f"{p}: objects[{i}]", lambda w, spec=spec: _object(scene, _Table(spec, w), base))
    lights = root.get("lights", [])
    if not isinstance(lights, list):
        raise SceneError(f"{p}: lights must be an array of tables ([[lights]])")
    for i, spec in enumerate(lights):
        _within(f"{p}: lights[{i}]", lambda w, spec=spec: _light(scene, _Table(spec, w)))
    if require_light and env is None and not scene.emitters and not scene.lights:
        raise SceneError(
            f"{p}: the scene has no light: add an [environment] table, an object with emission or a [[lights]] entry"
        )
    render_table = root.get("render", {})
    if not isinstance(render_table, dict):
        raise SceneError(f"{p}: [render]: expected a table, got {type(render_table).__name__}")
    defaults = read_render_table(render_table, f"{p}: [render]", SceneError)
    root.done()
    return scene, defaults


def _within(where: str, build):
    """Run ``build(where)``; prefix any user error that does not name its place yet with ``where``."""
    try:
        return build(where)
    except LightprobeError as exc:
        message = str(exc)
        if message.startswith(where.split(":")[0]):
            raise
        raise SceneError(f"{where}: {message}") from None
