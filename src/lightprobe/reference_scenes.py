"""Scenes described once, without reference to a renderer, and rendered by lightprobe and by Mitsuba 3.

Two sets: :data:`NAMES`, the test suite's four small references, and :data:`SUITE`, the benchmark suite's nine
scenes (``benchmarks/suite.py``, docs/performance.md), described at the end of this docstring.

The convergence tests of the suite compare lightprobe with itself: a bias that every strategy shares would pass
them.  These four scenes are described here once, without reference to a renderer (camera, environment,
materials, objects as plain numbers); :func:`build` makes the lightprobe scene and ``benchmarks/mitsuba_references.py``
makes Mitsuba 3's from the same description and writes the per-pixel mean and variance of its ``direct``
integrator's image to ``tests/data/mitsuba_<name>.npz`` (64 x 48 pixels, float32).  The tests z-test lightprobe's
strategies and light selectors against those images without needing Mitsuba.

``sky``
    an environment map alone (a sky with a 6-degree sun) over a ground, a smooth-shaded mesh, a rough aluminium
    sphere and a diffuse sphere;
``area``
    a rectangle light, a sphere light and a ring of 16 triangle lights over a 16 m ground under a dim constant sky,
    with a rough aluminium sphere, a diffuse sphere and a mesh (issue 33's area-light scene, small);
``many``
    600 small rectangle lights (``lights=`` another count) facing down, their radiances spread over three decades,
    over a ground, a rough aluminium sphere and a diffuse sphere; no environment;
``sunsky``
    the Hosek-Wilkie sun and sky (:class:`~lightprobe.emitters.sunsky.SunSky`: turbidity 3, the sun 35 degrees up
    in front of the camera on its right) over a 40 m ground, the blob, a rough aluminium sphere and a diffuse
    sphere; the camera looks down, so the horizon (where the baked map's last row of sky blurs into the black below
    it over a third of a degree) and the sun are out of view.  Mitsuba's side is its ``sunsky`` emitter with
    ``complex_sun`` (benchmarks/mitsuba_references.py).

The benchmark suite (:data:`SUITE`, 320 x 240; each stresses something else):

``peer``
    the peer scene of ``../shared/peers`` (an environment map with a 0.5-degree sun, a 98,000-triangle blob, rough
    conductors and plastic), built by :mod:`lightprobe.peer` from the kit's own description, not re-described here;
``area``
    as above, at the benchmark's resolution;
``ceiling``
    ``many`` with 2,000 panels: a grid of small lights all facing down (what a light BVH's orientation bounds like);
``dome``
    300 small rectangles on a partial dome around the objects, each facing their centre (lights from every
    direction), radiance over 2.5 decades, a dim constant sky, a rough gold ball, a red ball and a box;
``window``
    a closed room lit only through one window by a sky with a sun (most of the map hidden from every point inside:
    the map's samples mostly wasted), the sun's patch on the floor, objects inside;
``building``
    six rooms with doorways and 64 small ceiling lights in each, the camera in a dim room looking through a doorway
    into a bright one: most of the light power is behind walls (:func:`unoccluded_power_fraction`);
``gltf``
    a textured glTF asset (``examples/make_textured_asset.py``'s bunny, without its normal map) under a real HDR
    map with a small bright sun (``../shared/data``; skipped without it, :func:`unavailable`);
``glossy``
    rough conductors at alpha 0.02-0.2 (four spheres and the blob) under three small bright sphere lights and a dim
    sky: fireflies;
``city``
    100,000 lit windows (small rectangles facing out, 16 radiance levels over 1.5 decades, warm tints) on blocks of
    box buildings, a camera above a street, a very dim sky.

Conventions shared with Mitsuba: the horizontal field of view (``fov_axis = "x"``), a box pixel filter, lat-long
maps looked up as Mitsuba does, one-sided emitters that emit on the side of their normal (a rectangle's edge_u x
edge_v, a triangle's winding), conductors given by RGB eta and k.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

__all__ = ["NAMES", "SUITE", "build", "describe", "unavailable", "unoccluded_power_fraction"]

NAMES = ("sky", "area", "many", "sunsky")
SUNSKY = {"turbidity": 3.0, "albedo": 0.3, "sun_elevation": 35.0, "sun_azimuth": 60.0}
SUITE = ("peer", "area", "ceiling", "dome", "window", "building", "gltf", "glossy", "city")
RESOLUTION = (64, 48)
SUITE_RESOLUTION = (320, 240)
ALUMINIUM = {"eta": [1.6574599, 0.88036, 0.5212], "k": [9.2238691, 6.26954, 4.837]}
GOLD = {"eta": [0.14303598, 0.37530708, 1.4420453], "k": [3.982997, 2.3855565, 1.6033592]}  # Mitsuba's "Au"
CEILING_LIGHTS = 2000
CITY_WINDOWS = 100_000
CITY_LEVELS = 16
GLOSSY = (("aluminium", 0.02), ("gold", 0.05), ("aluminium", 0.1), ("gold", 0.2), ("aluminium", 0.08))
GLOSSY_LIGHTS = (  # centre, radius, radiance: small and bright
    ([-1.0, 1.6, -0.4], 0.015, [60000.0, 48000.0, 30000.0]),
    ([1.2, 1.3, 1.2], 0.03, [9000.0, 11000.0, 14000.0]),
    ([0.3, 2.2, -1.5], 0.05, [5000.0, 5000.0, 5000.0]),
)
GLTF_MAP = "usd_stinson_beach.hdr"  # a 1024 x 512 beach sky, its sun about 8 texels at 52 degrees elevation


def _materials() -> dict:
    return {
        "ground": {"model": "lambertian", "reflectance": [0.5, 0.5, 0.5]},
        "green": {"model": "lambertian", "reflectance": [0.2, 0.55, 0.25]},
        "red": {"model": "lambertian", "reflectance": [0.65, 0.2, 0.12]},
        "aluminium": {"model": "rough_conductor", "alpha": 0.2, **ALUMINIUM},
    }


def _ground(size: float) -> dict:
    half = size / 2
    return {"shape": "rectangle", "origin": [-half, 0.0, -half], "edge_u": [0.0, 0.0, size], "edge_v": [size, 0.0, 0.0]}


def _blob(scale: float, translate) -> dict:
    """The demo's blob (the icosphere of subdivision 2 with its bumps), smooth-shaded, as plain arrays."""
    from .demo import blob_mesh
    from .geometry.mesh import angle_weighted_normals

    mesh = blob_mesh(2)
    vertices = mesh.vertices * scale + np.asarray(translate, dtype=np.float64)
    return {
        "shape": "triangles",
        "vertices": vertices,
        "faces": mesh.faces,
        "normals": angle_weighted_normals(vertices, mesh.faces),
    }


def _ring(n: int, radius: float, height: float, width: float) -> dict:
    """``n`` triangles in a ring at ``height``, facing down."""
    angles = 2 * np.pi * np.arange(n) / n
    vertices, faces = [], []
    for i, a in enumerate(angles):
        b = a + 2 * np.pi / n * 0.8
        inner = radius - width / 2
        outer = radius + width / 2
        vertices += [
            [inner * math.cos(a), height, inner * math.sin(a)],
            [outer * math.cos(a), height, outer * math.sin(a)],
            [radius * math.cos(b), height, radius * math.sin(b)],
        ]
        faces.append([3 * i, 3 * i + 1, 3 * i + 2])
    v, f = np.array(vertices), np.array(faces)
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    flip = normal[:, 1] > 0  # every face toward the ground
    f[flip] = f[flip][:, [0, 2, 1]]
    return {"shape": "triangles", "vertices": v, "faces": f}


def _panels(n: int, seed: int) -> list[dict]:
    """``n`` small squares facing down over a 6 x 6 area at heights 1.9-2.5, radiances over three decades."""
    rng = np.random.default_rng(seed)
    centres = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(1.9, 2.5, n), rng.uniform(-3, 3, n)])
    size = rng.uniform(0.04, 0.12, n)
    angle = rng.uniform(0, np.pi / 2, n)
    level = 10.0 ** rng.uniform(0.0, 3.0, n) * 0.4
    tint = np.column_stack([np.ones(n), rng.uniform(0.6, 0.9, n), rng.uniform(0.3, 0.8, n)])
    panels = []
    for i in range(n):
        ex = size[i] * np.array([math.cos(angle[i]), 0.0, math.sin(angle[i])])
        ez = size[i] * np.array([-math.sin(angle[i]), 0.0, math.cos(angle[i])])
        # edge_u x edge_v = ex x ez = -Y: facing down
        panels.append(
            {
                "shape": "rectangle",
                "origin": centres[i] - (ex + ez) / 2,
                "edge_u": ex,
                "edge_v": ez,
                "emission": level[i] * tint[i],
            }
        )
    return panels


MANY_LIGHTS = 600  # the many-light scene's panels in the test references (the benchmarks take 2,000)


def _rect(origin, edge_u, edge_v, facing=None, **extra) -> dict:
    """A rectangle; with ``facing`` (a direction), its edges ordered so that its normal edge_u x edge_v points
    along it (one-sided emitters emit there, one-sided materials reflect there)."""
    o, u, v = (np.asarray(x, dtype=np.float64) for x in (origin, edge_u, edge_v))
    if facing is not None and np.dot(np.cross(u, v), facing) < 0:
        u, v = v, u
    return {"shape": "rectangle", "origin": o, "edge_u": u, "edge_v": v, **extra}


def _box(lo, hi, material: str, *, bottom: bool = False) -> list[dict]:
    """The faces of the axis-aligned box [lo, hi] as rectangles facing out (without its bottom face unless
    ``bottom``: a box standing on the ground)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    size = hi - lo
    faces = []
    for axis in range(3):
        a, b = (axis + 1) % 3, (axis + 2) % 3
        u, v = np.zeros(3), np.zeros(3)
        u[a], v[b] = size[a], size[b]
        for side, corner in ((-1.0, lo), (1.0, hi)):
            if axis == 1 and side < 0 and not bottom:
                continue
            origin = lo.copy()
            origin[axis] = corner[axis]
            normal = np.zeros(3)
            normal[axis] = side
            faces.append(_rect(origin, u, v, normal, material=material))
    return faces


def _dome_lights(n: int, seed: int, centre) -> list[dict]:
    """``n`` small squares on a partial dome (radius 2.4-3.2, elevation 8-70 degrees, every azimuth) around
    ``centre``, each facing it; radiances over 2.5 decades, warm and cool tints."""
    rng = np.random.default_rng(seed)
    c = np.asarray(centre, dtype=np.float64)
    azimuth = rng.uniform(0.0, 2.0 * np.pi, n)
    elevation = np.radians(rng.uniform(8.0, 70.0, n))
    radius = rng.uniform(2.4, 3.2, n)
    size = rng.uniform(0.06, 0.16, n)
    level = 10.0 ** rng.uniform(0.0, 2.5, n) * 0.6
    warm = rng.uniform(0.0, 1.0, n)
    tint = np.column_stack([0.75 + 0.25 * warm, 0.85 * np.ones(n), 1.0 - 0.45 * warm])
    lights = []
    for i in range(n):
        d = np.array([math.cos(elevation[i]) * math.sin(azimuth[i]), math.sin(elevation[i]),
                      math.cos(elevation[i]) * math.cos(azimuth[i])])  # fmt: skip
        p = c + radius[i] * d
        normal = -d
        t1 = np.cross(normal, [0.0, 1.0, 0.0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(normal, t1)  # t1 x t2 = normal
        u, v = size[i] * t1, size[i] * t2
        lights.append(_rect(p - (u + v) / 2, u, v, normal, emission=level[i] * tint[i]))
    return lights


def _wall_with_opening(x0, x1, y0, y1, z, facing, hole=None, *, material: str, two_sided=False) -> list[dict]:
    """A wall in the plane z = ``z`` (x from x0 to x1, y from y0 to y1) facing ``facing`` (+1 or -1 along z), with
    an optional rectangular opening ``hole`` = (hx0, hx1, hy0, hy1): the rectangles around it."""
    parts = []
    if hole is None:
        spans = [(x0, x1, y0, y1)]
    else:
        hx0, hx1, hy0, hy1 = hole
        spans = [(x0, hx0, y0, y1), (hx1, x1, y0, y1), (hx0, hx1, y0, hy0), (hx0, hx1, hy1, y1)]
    for a0, a1, b0, b1 in spans:
        if a1 - a0 <= 0 or b1 - b0 <= 0:
            continue
        extra = {"two_sided": True} if two_sided else {}
        parts.append(_rect([a0, b0, z], [a1 - a0, 0, 0], [0, b1 - b0, 0], [0, 0, facing], material=material, **extra))
    return parts


def _swap_xz(obj: dict) -> dict:
    """A rectangle mirrored through the plane x = z (x and z swapped), its normal kept mirrored too."""
    out = dict(obj)
    for key in ("origin", "edge_u", "edge_v"):
        out[key] = np.asarray(obj[key])[[2, 1, 0]]
    # the mirror reverses handedness: swap the edges so the normal is the mirrored normal
    out["edge_u"], out["edge_v"] = out["edge_v"], out["edge_u"]
    return out


def _window_room() -> list[dict]:
    """A closed room, x in [-2, 2], y in [0, 2.6], z in [-3, 3], every surface facing in, with one window
    (x in [-0.8, 0.8], y in [0.9, 2.1]) in the wall z = -3; the walls run 5 cm past the corners (light-tight)."""
    e = 0.05
    room = [
        _rect([-2 - e, 0, -3 - e], [4 + 2 * e, 0, 0], [0, 0, 6 + 2 * e], [0, 1, 0], material="floor"),
        _rect([-2 - e, 2.6, -3 - e], [4 + 2 * e, 0, 0], [0, 0, 6 + 2 * e], [0, -1, 0], material="wall"),
        *_wall_with_opening(-2 - e, 2 + e, -e, 2.6 + e, -3.0, 1.0, (-0.8, 0.8, 0.9, 2.1), material="wall"),
        *_wall_with_opening(-2 - e, 2 + e, -e, 2.6 + e, 3.0, -1.0, material="wall"),
    ]
    for x, facing in ((-2.0, 1.0), (2.0, -1.0)):  # side walls: the plane x = const, mirrored from z = const
        (wall,) = _wall_with_opening(-3 - e, 3 + e, -e, 2.6 + e, x, facing, material="wall")
        room.append(_swap_xz(wall))
    return room


BUILDING_ROOMS = (3, 2)  # rooms along x and z, each 4 m x 4 m, 2.8 m high
BUILDING_LIGHTS_PER_ROOM = 8  # a grid of 8 x 8 small ceiling lights per room


def _building() -> list[dict]:
    """Six rooms (3 x 2, x in [-6, 6], z in [-4, 4], 2.8 m high) with a doorway (1 m x 2.1 m) in every wall
    between two rooms; walls, floor and ceiling two-sided (seen from both rooms), overlapping at the edges; 64
    small square lights facing down under each room's ceiling, the camera's room (x < -2, z > 0) 30x dimmer than
    the others, the room through its doorway (-2 < x < 2, z > 0) the brightest."""
    h, e = 2.8, 0.02
    nx, nz = BUILDING_ROOMS
    x0, z0 = -2.0 * nx, -2.0 * nz
    objects = [
        _rect([x0 - e, 0, z0 - e], [4 * nx + 2 * e, 0, 0], [0, 0, 4 * nz + 2 * e], [0, 1, 0], material="floor"),
        _rect([x0 - e, h, z0 - e], [4 * nx + 2 * e, 0, 0], [0, 0, 4 * nz + 2 * e], [0, -1, 0], material="ceiling"),
    ]
    door = (1.0, 2.1)  # width, height

    def wall_z(z, xa, xb, doors, facing):  # a wall in the plane z = const from xa to xb, doorways centred at doors
        out, cursor = [], xa
        for d in doors:
            out += _wall_with_opening(cursor, d + door[0] / 2, -e, h + e, z, facing,
                                      (d - door[0] / 2, d + door[0] / 2, -e, door[1]), material="wall",
                                      two_sided=True)  # fmt: skip
            cursor = d + door[0] / 2
        out += _wall_with_opening(cursor, xb, -e, h + e, z, facing, material="wall", two_sided=True)
        return out

    # outer walls
    objects += wall_z(z0, x0 - e, -x0 + e, [], 1.0) + wall_z(-z0, x0 - e, -x0 + e, [], -1.0)
    for x, facing in ((x0, 1.0), (-x0, -1.0)):
        objects += [_swap_xz(w) for w in wall_z(x, z0 - e, -z0 + e, [], facing)]
    # inner walls: z = 0 across, a doorway into each room pair; x = -2 and x = 2, a doorway per row of rooms
    objects += wall_z(0.0, x0, -x0, [x0 + 2 + 4 * i for i in range(nx)], 1.0)
    for k in range(1, nx):
        x = x0 + 4 * k
        objects += [_swap_xz(w) for w in wall_z(x, z0, -z0, [z0 + 2 + 4 * j for j in range(nz)], 1.0)]
    # ceiling lights
    n, s = BUILDING_LIGHTS_PER_ROOM, 0.12
    rng = np.random.default_rng(57)
    for i in range(nx):
        for j in range(nz):
            cx, cz = x0 + 4 * i + 2, z0 + 4 * j + 2
            if (i, j) == (0, 1):
                level = 4.0  # the camera's room: dim
            elif (i, j) == (1, 1):
                level = 140.0  # seen through the doorway: bright
            else:
                level = 100.0
            for a in range(n):
                for b in range(n):
                    px = cx - 1.6 + 3.2 * (a + 0.5) / n
                    pz = cz - 1.6 + 3.2 * (b + 0.5) / n
                    tint = np.array([1.0, 0.9, 0.75]) * rng.uniform(0.7, 1.3)
                    objects.append(_rect([px - s / 2, h - 0.02, pz - s / 2], [s, 0, 0], [0, 0, s], [0, -1, 0],
                                         emission=level * tint))  # fmt: skip
    return objects


def _city(seed: int = 2026) -> tuple[list[dict], dict]:
    """(buildings as boxes of rectangles, the windows as one batch): blocks of 20 m x 20 m with 10 m streets, four
    buildings of 9 m x 9 m and 12-50 m high on each; windows 0.8 m x 1.2 m every 1.5 m along a facade and every
    2.5 m up it, 2 cm in front of it, facing out; :data:`CITY_WINDOWS` of the candidates lit, each at one of
    :data:`CITY_LEVELS` radiance levels (1.5 decades) and warm tints, quantised here so that every renderer sees the
    same 16 radiances."""
    rng = np.random.default_rng(seed)
    objects = []
    origins, edges_u, edges_v = [], [], []
    up = np.array([0.0, 1.0, 0.0])
    for bi in range(-4, 4):
        for bj in range(-11, 1):
            bx, bz = 30.0 * bi + 5.0, 30.0 * bj - 25.0  # the block's corner: x in [bx, bx + 20], z in [bz, bz + 20]
            for ox in (0.5, 10.5):
                for oz in (0.5, 10.5):
                    height = float(rng.uniform(12.0, 50.0))
                    lo = np.array([bx + ox, 0.0, bz + oz])
                    hi = lo + np.array([9.0, height, 9.0])
                    objects += _box(lo, hi, "facade")
                    floors = int((height - 2.0) // 2.5)
                    for normal, corner, along in (
                        ([0, 0, 1.0], [lo[0], 0, hi[2]], [1.0, 0, 0]),
                        ([0, 0, -1.0], [lo[0], 0, lo[2]], [1.0, 0, 0]),
                        ([1.0, 0, 0], [hi[0], 0, lo[2]], [0, 0, 1.0]),
                        ([-1.0, 0, 0], [lo[0], 0, lo[2]], [0, 0, 1.0]),
                    ):
                        n, a = np.array(normal), np.array(along)
                        u, v = np.cross(up, n) * 0.8, up * 1.2  # u x v = n
                        for col in range(6):
                            for row in range(floors):
                                centre = np.array(corner) + a * (0.75 + 1.5 * col) + up * (2.0 + 2.5 * row) + 0.02 * n
                                origins.append(centre - (u + v) / 2)
                                edges_u.append(u)
                                edges_v.append(v)
    origins, edges_u, edges_v = np.array(origins), np.array(edges_u), np.array(edges_v)
    if origins.shape[0] < CITY_WINDOWS:
        raise AssertionError(f"the city has {origins.shape[0]} windows, fewer than {CITY_WINDOWS}")
    lit = np.sort(rng.choice(origins.shape[0], CITY_WINDOWS, replace=False))
    k = np.arange(CITY_LEVELS)
    warmth = (k * 7 % CITY_LEVELS) / (CITY_LEVELS - 1)  # tints spread over the levels
    levels = (1.5 * 10.0 ** (1.5 * k / (CITY_LEVELS - 1)))[:, None] * np.column_stack(
        [np.ones(CITY_LEVELS), 0.78 + 0.12 * (1 - warmth), 0.45 + 0.3 * (1 - warmth)]
    )
    level = rng.integers(0, CITY_LEVELS, CITY_WINDOWS)
    windows = {
        "shape": "rectangles",
        "origins": origins[lit],
        "edges_u": edges_u[lit],
        "edges_v": edges_v[lit],
        "levels": levels,  # (16, 3): the radiances
        "level": level,  # (N,): each window's
    }
    return objects, windows


def _gltf_asset() -> Path | None:
    """The suite's textured glTF asset (examples/make_textured_asset.py's bunny, 512-texel textures, its normal
    map removed), made once into the user's cache; None when the shared data or the examples are missing."""
    from .data import data_dir

    root = data_dir()
    maker = Path(__file__).resolve().parents[2] / "examples" / "make_textured_asset.py"
    if root is None or not (root / "meshes" / "stanford_bunny_pymeshlab.obj").exists() or not maker.exists():
        return None
    folder = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "lightprobe-suite" / "assets"
    out = folder / "textured_bunny_suite.glb"
    if not out.exists():
        import importlib.util
        import tempfile

        spec = importlib.util.spec_from_file_location("_make_textured_asset", maker)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            full = module.main(Path(tmp) / "full.glb", size=512)
            _without_normal_maps(full, Path(tmp) / "suite.glb")
            os.replace(Path(tmp) / "suite.glb", out)
    return out


def _without_normal_maps(src: Path, dst: Path) -> None:
    """Copy a GLB without its materials' ``normalTexture`` (the image stays in the buffer, unused): Mitsuba's
    normal map builds its tangent frame from the surface's dp/du, lightprobe's from MikkTSpace tangents, so a
    normal-mapped asset would differ between the renderers for that reason alone."""
    import json
    import struct

    raw = src.read_bytes()
    (json_size,) = struct.unpack_from("<I", raw, 12)
    doc = json.loads(raw[20 : 20 + json_size])
    for material in doc.get("materials", []):
        material.pop("normalTexture", None)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = raw[20 + json_size :]
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + rest
    dst.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)


def unavailable(name: str) -> str | None:
    """Why suite scene ``name`` cannot be built here (one line), or None."""
    if name == "peer":
        from .peer import find_peers

        return None if find_peers() is not None else "the peer kit (../shared/peers) is not here"
    if name == "gltf":
        from .data import data_dir

        root = data_dir()
        if root is None:
            return "../shared/data is not here (LIGHTPROBE_DATA)"
        for need in (root / "meshes" / "stanford_bunny_pymeshlab.obj", root / "envmaps" / GLTF_MAP):
            if not need.exists():
                return f"{need} is missing"
        if _gltf_asset() is None:
            return "examples/make_textured_asset.py is not beside the package"
    return None


def describe(name: str, *, lights: int | None = None) -> dict:
    """The renderer-neutral description of scene ``name`` (one of :data:`NAMES`); ``lights``: the many-light
    scene's number of panels (default :data:`MANY_LIGHTS`)."""
    if lights is not None and (name != "many" or lights < 1):
        raise ValueError(f"lights={lights!r}: only the many-light scene takes a count of lights, at least 1")
    materials = _materials()
    if name == "sky":
        return {
            "name": name,
            "camera": {"origin": [0.0, 1.4, 4.2], "target": [0.0, 0.45, 0.0], "fov": 45.0},
            "environment": {
                "sky": {"width": 256, "height": 128, "sun_elevation": 40.0, "sun_azimuth": 60.0},
                "sun_diameter": 6.0,
                "sun_radiance": [300.0, 280.0, 250.0],
            },
            "materials": materials,
            "objects": [
                {**_ground(16.0), "material": "ground"},
                {**_blob(0.5, [0.15, 0.55, -0.4]), "material": "red"},
                {"shape": "sphere", "center": [-1.1, 0.45, 0.2], "radius": 0.45, "material": "aluminium"},
                {"shape": "sphere", "center": [1.1, 0.3, 0.4], "radius": 0.3, "material": "green"},
            ],
        }
    if name == "area":
        return {
            "name": name,
            "camera": {"origin": [0.0, 1.7, 4.6], "target": [0.0, 0.5, 0.0], "fov": 50.0},
            "environment": {"constant": [0.04, 0.05, 0.07]},
            "materials": materials,
            "objects": [
                {**_ground(16.0), "material": "ground"},
                {**_blob(0.45, [0.2, 0.5, -0.5]), "material": "red"},
                {"shape": "sphere", "center": [-1.1, 0.45, 0.2], "radius": 0.45, "material": "aluminium"},
                {"shape": "sphere", "center": [1.2, 0.3, 0.5], "radius": 0.3, "material": "green"},
                {
                    "shape": "rectangle",
                    "origin": [-1.6, 1.9, -1.2],
                    "edge_u": [0.0, 0.0, 0.6],
                    "edge_v": [0.6, 0.0, 0.0],
                    "emission": [12.0, 11.0, 9.0],
                },
                {"shape": "sphere", "center": [1.4, 1.3, -0.6], "radius": 0.12, "emission": [60.0, 45.0, 30.0]},
                {**_ring(16, 0.9, 2.3, 0.12), "emission": [6.0, 7.0, 9.0]},
            ],
        }
    if name == "sunsky":
        return {
            "name": name,
            "camera": {"origin": [0.0, 2.6, 4.2], "target": [0.0, 0.3, 0.0], "fov": 45.0},
            "environment": {"sunsky": dict(SUNSKY)},
            "materials": materials,
            "objects": [
                {**_ground(40.0), "material": "ground"},
                {**_blob(0.5, [0.15, 0.55, -0.4]), "material": "red"},
                {"shape": "sphere", "center": [-1.1, 0.45, 0.2], "radius": 0.45, "material": "aluminium"},
                {"shape": "sphere", "center": [1.1, 0.3, 0.4], "radius": 0.3, "material": "green"},
            ],
        }
    if name == "many":
        return {
            "name": name,
            "camera": {"origin": [0.0, 1.6, 5.5], "target": [0.0, 0.5, 0.0], "fov": 50.0},
            "environment": None,
            "materials": materials,
            "objects": [
                {**_ground(16.0), "material": "ground"},
                {"shape": "sphere", "center": [-1.0, 0.5, 0.0], "radius": 0.5, "material": "aluminium"},
                {"shape": "sphere", "center": [0.9, 0.4, 0.5], "radius": 0.4, "material": "green"},
                *_panels(lights or MANY_LIGHTS, seed=17),
            ],
        }
    if name in SUITE:
        return _describe_suite(name, materials)
    raise ValueError(f"unknown reference scene {name!r}; known: {', '.join(NAMES + SUITE)}")


def _describe_suite(name: str, materials: dict) -> dict:
    materials = {
        **materials,
        "gold": {"model": "rough_conductor", "alpha": 0.2, **GOLD},
        "wall": {"model": "lambertian", "reflectance": [0.7, 0.68, 0.62]},
        "floor": {"model": "lambertian", "reflectance": [0.45, 0.35, 0.25]},
        "ceiling": {"model": "lambertian", "reflectance": [0.8, 0.8, 0.8]},
        "box": {"model": "lambertian", "reflectance": [0.3, 0.45, 0.7]},
    }
    if name == "peer":
        return {"name": name, "peer_kit": True}  # lightprobe.peer's scene: ../shared/peers/scene.json
    if name == "area":
        return describe("area")
    if name == "ceiling":
        return {**describe("many", lights=CEILING_LIGHTS), "name": name}
    if name == "dome":
        centre = [0.0, 0.45, 0.0]
        return {
            "name": name,
            "camera": {"origin": [0.4, 2.2, 6.4], "target": [0.0, 0.5, 0.0], "fov": 55.0},
            "environment": {"constant": [0.02, 0.025, 0.035]},
            "materials": materials,
            "objects": [
                {**_ground(16.0), "material": "ground"},
                {"shape": "sphere", "center": [-0.9, 0.45, 0.1], "radius": 0.45, "material": "gold"},
                {"shape": "sphere", "center": [0.8, 0.35, 0.5], "radius": 0.35, "material": "red"},
                *_box([0.1, 0.0, -1.0], [0.8, 0.6, -0.3], "box"),
                *_dome_lights(300, seed=23, centre=centre),
            ],
        }
    if name == "window":
        return {
            "name": name,
            "camera": {"origin": [1.5, 1.55, 2.75], "target": [-0.35, 0.55, -1.2], "fov": 70.0},
            "environment": {
                "sky": {"width": 512, "height": 256, "sun_elevation": 38.0, "sun_azimuth": 10.0, "scale": 4.0},
                "sun_diameter": 2.0,
                "sun_radiance": [9000.0, 8500.0, 7500.0],
            },
            "materials": materials,
            "objects": [
                *_window_room(),
                {"shape": "sphere", "center": [-0.6, 0.4, -1.0], "radius": 0.4, "material": "aluminium"},
                {"shape": "sphere", "center": [0.9, 0.3, -0.3], "radius": 0.3, "material": "red"},
                {**_blob(0.35, [-1.2, 0.38, 0.6]), "material": "green"},
                *_box([-1.8, 0.0, -2.4], [-1.1, 0.6, -1.7], "box"),
            ],
        }
    if name == "building":
        return {
            "name": name,
            "camera": {"origin": [-5.4, 1.6, 3.5], "target": [1.0, 1.0, 1.7], "fov": 75.0},
            "environment": None,
            "materials": materials,
            "objects": [
                *_building(),
                {"shape": "sphere", "center": [0.3, 0.5, 2.4], "radius": 0.5, "material": "aluminium"},
                {"shape": "sphere", "center": [-4.0, 0.4, 2.2], "radius": 0.4, "material": "red"},
                *_box([-0.9, 0.0, 0.8], [-0.1, 0.8, 1.5], "box"),
            ],
        }
    if name == "gltf":
        from .data import data_dir
        from .errors import SceneError

        reason = unavailable(name)
        if reason is not None:
            raise SceneError(f"suite scene gltf: {reason}")
        root = data_dir()
        return {
            "name": name,
            "camera": {"origin": [0.35, 0.95, 2.3], "target": [0.0, 0.42, 0.0], "fov": 40.0},
            "environment": {"file": str(root / "envmaps" / GLTF_MAP) if root else None},
            "materials": materials,
            "objects": [{"shape": "gltf", "file": str(_gltf_asset())}],
        }
    if name == "glossy":
        glossy = {
            f"{metal}{alpha}": {"model": "rough_conductor", "alpha": alpha, **(GOLD if metal == "gold" else ALUMINIUM)}
            for metal, alpha in GLOSSY
        }
        return {
            "name": name,
            "camera": {"origin": [0.0, 1.5, 4.8], "target": [0.0, 0.45, 0.0], "fov": 50.0},
            "environment": {"constant": [0.01, 0.012, 0.018]},
            "materials": {**materials, **glossy},
            "objects": [
                {**_ground(16.0), "material": "ground"},
                {"shape": "sphere", "center": [-1.3, 0.4, 0.3], "radius": 0.4, "material": "aluminium0.02"},
                {"shape": "sphere", "center": [-0.4, 0.35, 0.9], "radius": 0.35, "material": "gold0.05"},
                {"shape": "sphere", "center": [0.6, 0.45, 0.6], "radius": 0.45, "material": "aluminium0.1"},
                {"shape": "sphere", "center": [1.5, 0.3, 0.1], "radius": 0.3, "material": "gold0.2"},
                {**_blob(0.5, [0.0, 0.55, -0.7]), "material": "aluminium0.08"},
                *({"shape": "sphere", "center": c, "radius": r, "emission": e} for c, r, e in GLOSSY_LIGHTS),
            ],
        }
    # city
    buildings, windows = _city()
    return {
        "name": name,
        "camera": {"origin": [0.0, 16.0, 18.0], "target": [0.0, 2.0, -60.0], "fov": 65.0},
        "environment": {"constant": [0.002, 0.0025, 0.004]},
        "materials": {
            **materials,
            "facade": {"model": "lambertian", "reflectance": [0.35, 0.33, 0.3]},
            "street": {"model": "lambertian", "reflectance": [0.25, 0.25, 0.25]},
        },
        "objects": [{**_ground(800.0), "material": "street"}, *buildings, windows],
    }


def environment_image(desc: dict) -> np.ndarray | None:
    """The scene's lat-long environment image (H, W, 3) float32, or None (also for a map read from a file: see
    ``desc["environment"]["file"]``)."""
    from .emitters.procedural import constant, sky_with_sun

    env = desc["environment"]
    if env is None or "file" in env or "sunsky" in env:  # a sunsky's map is its own (build())
        return None
    if "constant" in env:
        return constant(env["constant"], width=8, height=4)
    sky = env["sky"]
    scale = sky.get("scale", 1.0)  # the sky's gradient and ground times this (the sun as given)
    return sky_with_sun(
        sky["width"],
        sky["height"],
        sun_elevation_deg=sky["sun_elevation"],
        sun_azimuth_deg=sky["sun_azimuth"],
        sun_diameter_deg=env["sun_diameter"],
        sun_radiance=env["sun_radiance"],
        zenith=scale * np.array([0.25, 0.4, 0.85]),
        horizon=scale * np.array([0.85, 0.9, 1.0]),
        ground=scale * np.array([0.12, 0.1, 0.08]),
    )


def expand_rectangles(batch: dict) -> list[dict]:
    """A ``rectangles`` batch of a description (the city's windows) as one rectangle dict each."""
    emission = batch["levels"][batch["level"]]
    return [
        {"shape": "rectangle", "origin": o, "edge_u": u, "edge_v": v, "emission": e}
        for o, u, v, e in zip(batch["origins"], batch["edges_u"], batch["edges_v"], emission, strict=True)
    ]


def build(
    name: str,
    *,
    lights_as_mesh: bool = False,
    resolution: tuple[int, int] | None = None,
    lights: int | None = None,
):
    """The lightprobe :class:`~lightprobe.scene.Scene` of reference scene ``name`` (of :data:`NAMES` or
    :data:`SUITE`).  ``lights_as_mesh``: the rectangle lights as one emissive mesh of two triangles each, one
    radiance per face (the same emitters); ``resolution``: the image size (default: the test references' 64 x 48
    for :data:`NAMES`, :data:`SUITE_RESOLUTION` for the suite's other scenes); ``lights``: as :func:`describe`."""
    from .bsdfs import GGXConductor, Lambert
    from .emitters.envmap import EnvironmentMap
    from .geometry.camera import Camera
    from .geometry.mesh import TriangleMesh
    from .geometry.shapes import Rectangle, Sphere
    from .scene import Scene

    if resolution is None:
        resolution = RESOLUTION if name in NAMES else SUITE_RESOLUTION
    if name == "peer":
        from .peer import peer_scene

        return peer_scene(resolution=tuple(resolution))
    desc = describe(name, lights=lights)
    cam = desc["camera"]
    camera = Camera(cam["origin"], cam["target"], fov=cam["fov"], fov_axis="x", resolution=tuple(resolution))
    env = desc["environment"]
    sun = None
    if env is not None and "file" in env:
        environment = EnvironmentMap.load(env["file"])
    elif env is not None and "sunsky" in env:
        from .emitters.sunsky import SunSky

        sky = SunSky(**env["sunsky"])
        environment, sun = sky.environment(), sky.sun()
    else:
        image = environment_image(desc)
        environment = None if image is None else EnvironmentMap.from_array(image)
    scene = Scene(camera, environment, name=f"reference {name}")
    if sun is not None:
        scene.add_light(sun)
    for key, m in desc["materials"].items():
        if m["model"] == "lambertian":
            scene.add_material(key, Lambert(m["reflectance"]))
        else:
            scene.add_material(key, GGXConductor(m["alpha"], eta=m["eta"], k=m["k"]))
    quads = []
    objects = []
    for o in desc["objects"]:
        objects += expand_rectangles(o) if o["shape"] == "rectangles" else [o]
    for i, o in enumerate(objects):
        extra = {"emission": o["emission"]} if "emission" in o else {}
        material = o.get("material")
        label = f"object {i}"
        two_sided = bool(o.get("two_sided", False))
        if o["shape"] == "rectangle":
            if lights_as_mesh and "emission" in o:
                quads.append(o)
                continue
            rect = Rectangle(o["origin"], o["edge_u"], o["edge_v"])
            scene.add(rect, material, name=label, two_sided=two_sided, **extra)
        elif o["shape"] == "sphere":
            scene.add(Sphere(o["center"], o["radius"]), material, name=label, two_sided=two_sided, **extra)
        elif o["shape"] == "gltf":
            from .io.gltf import load_gltf

            load_gltf(o["file"]).add_to(scene, name=f"{label} (glTF)")
        else:
            mesh = TriangleMesh.from_arrays(
                o["vertices"], o["faces"], o.get("normals"), smooth="normals" in o, name=label
            )
            scene.add(mesh, material, name=label, two_sided=two_sided, **extra)
    if quads:
        # as arrays: a scene's description may give its vectors as lists, whose + would concatenate
        corners = [tuple(np.asarray(q[key], np.float64) for key in ("origin", "edge_u", "edge_v")) for q in quads]
        vertices = np.concatenate([[o, o + u, o + u + v, o + v] for o, u, v in corners])
        base = 4 * np.arange(len(quads))[:, None]
        faces = (base + np.array([0, 1, 2, 0, 2, 3])).reshape(-1, 3)
        radiance = np.repeat(np.array([q["emission"] for q in quads]), 2, axis=0)
        mesh = TriangleMesh.from_arrays(vertices, faces, smooth=False, name="lights")
        scene.add(mesh, name="lights", emission=radiance)
    return scene


def unoccluded_power_fraction(scene, *, stride: int = 4, points_per_light: int = 2) -> float:
    """The share of the scene's area-light power that reaches the points the camera sees unoccluded, averaged over
    those points: for the first hit x of the ray through the centre of every ``stride``-th pixel (in x and y; rays
    that miss are left out), sum over lights of power x the fraction of the light's test points (a
    ``points_per_light`` x ``points_per_light`` grid of cell centres on a rectangle or triangle; a sphere's centre)
    whose segment to x is free and on the emitting side of a one-sided light, over the total power; then the mean
    over the points.  Power is pi A L (luminance; two-sided lights twice: ``emitters.area.area_power``).  A light
    behind the surface at x counts as hidden (the segment starts on the camera's side of x).  Small values mean that
    most of the light a renderer samples is behind walls."""
    from .emitters.area import area_power
    from .emitters.kinds import area_rows, rows_of
    from .geometry.raytracer import RayTracer

    lights = scene.light_table()
    area = area_rows(lights.kind)
    if not area.any():
        raise ValueError("the scene has no area lights")
    power = area_power(lights)[area]
    geom, two_sided = lights.geom[area], lights.two_sided[area]
    rectangle, triangle = rows_of(lights.kind, "rectangle")[area], rows_of(lights.kind, "triangle")[area]
    sphere = rows_of(lights.kind, "sphere")[area]
    k = points_per_light
    cells = (np.arange(k) + 0.5) / k
    a, b = (x.ravel() for x in np.meshgrid(cells, cells))
    targets, normals, owner, weight = [], [], [], []
    for i, g in enumerate(geom):
        if rectangle[i]:
            p = g[0:3] + a[:, None] * g[3:6] + b[:, None] * g[6:9]
            n = np.cross(g[3:6], g[6:9])
        elif triangle[i]:
            keep = a + b < 1.0 + 1e-12  # cell centres inside the triangle (the square's lower half)
            aa, bb = a[keep], b[keep]
            p = g[0:3] + aa[:, None] * (g[3:6] - g[0:3]) + bb[:, None] * (g[6:9] - g[0:3])
            n = np.cross(g[3:6] - g[0:3], g[6:9] - g[0:3])
        else:
            p, n = g[None, 0:3], np.zeros(3)
        targets.append(p)
        normals.append(np.broadcast_to(n / max(np.linalg.norm(n), 1e-300), p.shape))
        owner.append(np.full(p.shape[0], i))
        weight.append(np.full(p.shape[0], power[i] / p.shape[0]))
    targets, normals = np.concatenate(targets), np.concatenate(normals)
    owner, weight = np.concatenate(owner), np.concatenate(weight)
    radius = np.where(sphere, geom[:, 3], 0.0)[owner]
    one_sided = (~sphere & (two_sided == 0))[owner]

    width, height = scene.camera.resolution
    ys, xs = np.mgrid[0:height:stride, 0:width:stride]
    pixels = (ys * width + xs).ravel()
    origins, dirs = scene.camera.rays(pixels, np.full((pixels.size, 2), 0.5))
    tracer = RayTracer(scene.compile())
    try:
        t, *_ = tracer.intersect(origins, dirs)
        seen = np.isfinite(t)
        points = origins[seen] + (t[seen] * (1.0 - 1e-6) - 1e-5)[:, None] * dirs[seen]  # on the camera's side
        shares = np.empty(points.shape[0])
        chunk = max(1, 200_000 // targets.shape[0])  # points per batch of shadow rays
        for start in range(0, points.shape[0], chunk):
            x = points[start : start + chunk, None, :]  # (P, 1, 3)
            d = targets[None, :, :] - x  # (P, T, 3)
            dist = np.linalg.norm(d, axis=2)
            d /= dist[..., None]
            facing = ~one_sided[None, :] | (np.einsum("tj,ptj->pt", normals, d) < 0.0)
            tmax = (dist - radius[None, :]) * (1.0 - 1e-6)
            origin = np.broadcast_to(x, d.shape).reshape(-1, 3)
            blocked = tracer.occluded(origin, d.reshape(-1, 3), tmax.ravel()).reshape(dist.shape)
            shares[start : start + chunk] = ((facing & ~blocked) * weight[None, :]).sum(axis=1)
    finally:
        tracer.close()
    return float(shares.mean() / power.sum()) if shares.size else 0.0
