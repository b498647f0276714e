"""Small scenes rendered by an independent renderer (Mitsuba 3) as references for the test suite.

The convergence tests of the suite compare lightprobe with itself: a bias that every strategy shares would pass
them.  These three scenes are described here once, without reference to a renderer (camera, environment,
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
    over a ground, a rough aluminium sphere and a diffuse sphere; no environment.

Conventions shared with Mitsuba: the horizontal field of view (``fov_axis = "x"``), a box pixel filter, lat-long
maps looked up as Mitsuba does, one-sided emitters that emit on the side of their normal (a rectangle's edge_u x
edge_v, a triangle's winding), conductors given by RGB eta and k.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["NAMES", "build", "describe"]

NAMES = ("sky", "area", "many")
RESOLUTION = (64, 48)
ALUMINIUM = {"eta": [1.6574599, 0.88036, 0.5212], "k": [9.2238691, 6.26954, 4.837]}


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
    raise ValueError(f"unknown reference scene {name!r}; known: {', '.join(NAMES)}")


def environment_image(desc: dict) -> np.ndarray | None:
    """The scene's lat-long environment image (H, W, 3) float32, or None."""
    from .emitters.procedural import constant, sky_with_sun

    env = desc["environment"]
    if env is None:
        return None
    if "constant" in env:
        return constant(env["constant"], width=8, height=4)
    sky = env["sky"]
    return sky_with_sun(
        sky["width"],
        sky["height"],
        sun_elevation_deg=sky["sun_elevation"],
        sun_azimuth_deg=sky["sun_azimuth"],
        sun_diameter_deg=env["sun_diameter"],
        sun_radiance=env["sun_radiance"],
    )


def build(
    name: str, *, lights_as_mesh: bool = False, resolution: tuple[int, int] = RESOLUTION, lights: int | None = None
):
    """The lightprobe :class:`~lightprobe.geometry.scene.Scene` of reference scene ``name``.  ``lights_as_mesh``:
    the rectangle lights as one emissive mesh of two triangles each, one radiance per face (the same emitters);
    ``resolution``: another image size (the benchmarks'; the references are 64 x 48); ``lights``: as
    :func:`describe`."""
    from .bsdfs import GGXConductor, Lambert
    from .emitters.envmap import EnvironmentMap
    from .geometry.camera import Camera
    from .geometry.mesh import TriangleMesh
    from .geometry.scene import Scene
    from .geometry.shapes import Rectangle, Sphere

    desc = describe(name, lights=lights)
    cam = desc["camera"]
    camera = Camera(cam["origin"], cam["target"], fov=cam["fov"], fov_axis="x", resolution=resolution)
    image = environment_image(desc)
    scene = Scene(camera, None if image is None else EnvironmentMap.from_array(image), name=f"reference {name}")
    for key, m in desc["materials"].items():
        if m["model"] == "lambertian":
            scene.add_material(key, Lambert(m["reflectance"]))
        else:
            scene.add_material(key, GGXConductor(m["alpha"], eta=m["eta"], k=m["k"]))
    quads = []
    for i, o in enumerate(desc["objects"]):
        extra = {"emission": o["emission"]} if "emission" in o else {}
        material = o.get("material")
        label = f"object {i}"
        if o["shape"] == "rectangle":
            if lights_as_mesh and "emission" in o:
                quads.append(o)
                continue
            scene.add(Rectangle(o["origin"], o["edge_u"], o["edge_v"]), material, name=label, **extra)
        elif o["shape"] == "sphere":
            scene.add(Sphere(o["center"], o["radius"]), material, name=label, **extra)
        else:
            mesh = TriangleMesh.from_arrays(
                o["vertices"], o["faces"], o.get("normals"), smooth="normals" in o, name=label
            )
            scene.add(mesh, material, name=label, **extra)
    if quads:
        corners = [(q["origin"], q["edge_u"], q["edge_v"]) for q in quads]
        vertices = np.concatenate([[o, o + u, o + u + v, o + v] for o, u, v in corners])
        base = 4 * np.arange(len(quads))[:, None]
        faces = (base + np.array([0, 1, 2, 0, 2, 3])).reshape(-1, 3)
        radiance = np.repeat(np.array([q["emission"] for q in quads]), 2, axis=0)
        mesh = TriangleMesh.from_arrays(vertices, faces, smooth=False, name="lights")
        scene.add(mesh, name="lights", emission=radiance)
    return scene
