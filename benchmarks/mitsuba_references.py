#!/usr/bin/env python3
"""Render the suite's independent references with Mitsuba 3: ``tests/data/mitsuba_<name>.npz``.

    pip install -e '.[peers]'                 # Mitsuba 3.9.1 and Dr.Jit 1.5 (Debian: apt-get install libllvm19)
    python benchmarks/mitsuba_references.py   # every scene of lightprobe.reference_scenes, ~5 minutes on 2 cores
    python benchmarks/mitsuba_references.py --scenes area --passes 8

Each scene of :mod:`lightprobe.reference_scenes` is built in Mitsuba from the same renderer-neutral description
that lightprobe's builder reads, and rendered by Mitsuba's ``direct`` integrator (1 emitter + 1 BSDF sample, the
``multijitter`` sampler) in ``--passes`` independent passes of ``--spp`` samples per pixel.  The file holds the
mean image (H, W, 3), the variance of that mean (the passes' sample variance / passes), the total samples per pixel
and the command's settings, float32; the tests z-test lightprobe against it (tests/integrators/test_references.py).
The reference's own noise must stay far below what it judges: the script prints its relMSE floor,
mean(var / (mean^2 + 0.01)).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# suite scenes with a test reference too, at the test references' 64 x 48 (the building: learned light selection's
# z-test, tests/integrators/test_light_learning.py)
TEST_SUITE_SCENES = ("building",)


_LIBRARY_FOLDERS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib")


def _prefer_llvm19() -> None:
    """Dr.Jit 1.5 aborts with Debian 12's LLVM 15; point it at libLLVM 19 when installed (as the peer kit does).
    Without it, and with no libLLVM newer than 15 on the machine, say so on one line before Mitsuba runs: an
    in-process render aborts with LLVM's dump and no word of the remedy (:data:`LLVM_REMEDY`)."""
    if "DRJIT_LIBLLVM_PATH" in os.environ:
        return
    for folder in _LIBRARY_FOLDERS:
        for pattern in ("libLLVM-19.so", "libLLVM.so.19*", "libLLVM-19*.so*"):
            hits = sorted(glob.glob(os.path.join(folder, pattern)))
            if hits:
                os.environ["DRJIT_LIBLLVM_PATH"] = hits[0]
                return
    versions = [int(m.group(1)) for folder in _LIBRARY_FOLDERS for name in glob.glob(os.path.join(folder, "libLLVM*"))
                if (m := re.search(r"libLLVM[-.](?:so\.)?(\d+)", os.path.basename(name)))]  # fmt: skip
    if versions and max(versions) <= 15:
        print(f"warning: only libLLVM {max(versions)} found; if Mitsuba aborts with '{_LLVM_CRASH}': {LLVM_REMEDY}",
              file=sys.stderr, flush=True)  # fmt: skip


# What Dr.Jit 1.5 prints, and then aborts, when an older libLLVM (Debian 12's 15) cannot emit its kernels for this CPU
# (an AVX-512 one: "Cannot select: ... fminimum"); every Mitsuba render of the run would fail the same way
_LLVM_CRASH = "LLVM ERROR: Cannot select"
LLVM_REMEDY = (
    "Mitsuba's llvm_ad_rgb variant aborted in LLVM's code generator: Dr.Jit 1.5 cannot use this machine's libLLVM "
    "(Debian 12's LLVM 15); install libLLVM 19 (Debian 12: apt-get install libllvm19, found by itself) or point "
    "DRJIT_LIBLLVM_PATH at it (../shared/peers/README.md)"
)


def llvm_crash(stderr: str) -> str | None:
    """The one-line remedy when a Mitsuba worker's ``stderr`` is Dr.Jit's crash in an older libLLVM (a 40-line dump of
    LLVM's selection DAG otherwise), else None."""
    return LLVM_REMEDY if _LLVM_CRASH in stderr else None


def _rgb(value) -> dict:
    return {"type": "rgb", "value": [float(x) for x in np.broadcast_to(np.asarray(value, dtype=np.float64), 3)]}


def _bsdf(material: dict) -> dict:
    if material["model"] == "lambertian":
        return {"type": "diffuse", "reflectance": _rgb(material["reflectance"])}
    return {
        "type": "roughconductor",
        "distribution": "ggx",
        "alpha": float(material["alpha"]),
        "eta": _rgb(material["eta"]),
        "k": _rgb(material["k"]),
    }


def _black() -> dict:
    return {"type": "diffuse", "reflectance": _rgb(0.0)}


def _power(o: dict) -> float:
    """pi A L of an emissive object of a scene description, L the luminance of its radiance."""
    from lightprobe.color import luminance

    if o["shape"] == "rectangle":
        area = float(np.linalg.norm(np.cross(o["edge_u"], o["edge_v"])))
    elif o["shape"] == "sphere":
        area = 4.0 * np.pi * float(o["radius"]) ** 2
    else:
        v = np.asarray(o["vertices"], np.float64)[np.asarray(o["faces"])]
        area = float(0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum())
    return float(np.pi * area * luminance(np.asarray(o["emission"], np.float64)))


def _ply(mi, folder: str, name: str, vertices, faces, normals=None, uvs=None) -> str:
    """A triangle mesh written as a PLY file in ``folder`` (Mitsuba's mesh emitters and BSDFs are attached when a
    shape is loaded, so meshes go through files)."""
    vertices, faces = np.asarray(vertices, np.float32), np.asarray(faces, np.uint32)
    mesh = mi.Mesh(
        name,
        vertices.shape[0],
        faces.shape[0],
        has_vertex_normals=normals is not None,
        has_vertex_texcoords=uvs is not None,
    )
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(vertices.ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    if normals is not None:
        params["vertex_normals"] = mi.Float(np.asarray(normals, np.float32).ravel())
    if uvs is not None:
        params["vertex_texcoords"] = mi.Float(np.asarray(uvs, np.float32).ravel())
    params.update()
    ply = str(Path(folder) / f"{name}.ply")
    mesh.write_ply(ply)
    return ply


def _quads(origins, edges_u, edges_v) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of rectangles as two triangles each, wound so that the normal is edge_u x edge_v."""
    o, u, v = (np.asarray(x, np.float64) for x in (origins, edges_u, edges_v))
    vertices = np.stack([o, o + u, o + u + v, o + v], axis=1).reshape(-1, 3)
    base = 4 * np.arange(o.shape[0])[:, None]
    return vertices, (base + np.array([0, 1, 2, 0, 2, 3])).reshape(-1, 3)


def _window_groups(mi, batch: dict, folder: str, index: int, power_weights: bool) -> dict:
    """A ``rectangles`` batch (the city's windows) as one mesh per radiance level, each with an ``area`` emitter:
    100,000 shape dicts would take Mitsuba minutes to load.  With ``power_weights`` each mesh's sampling weight is
    its power (Mitsuba then samples a point on it by area, which within one level is by power)."""
    from lightprobe.color import luminance

    shapes = {}
    areas = np.linalg.norm(np.cross(batch["edges_u"], batch["edges_v"]), axis=1)
    for k, radiance in enumerate(batch["levels"]):
        mine = batch["level"] == k
        if not mine.any():
            continue
        vertices, faces = _quads(batch["origins"][mine], batch["edges_u"][mine], batch["edges_v"][mine])
        ply = _ply(mi, folder, f"windows{index}_{k}", vertices, faces)
        shape = {"type": "ply", "filename": ply, "bsdf": _black(), "face_normals": True}
        shape["emitter"] = {"type": "area", "radiance": _rgb(radiance)}
        if power_weights:
            shape["emitter"]["sampling_weight"] = float(np.pi * areas[mine].sum() * luminance(np.asarray(radiance)))
        shapes[f"object{index}_level{k}"] = shape
    return shapes


def _gltf_shapes(mi, path: str, folder: str, index: int) -> dict:
    """The primitives of a GLB file as PLY meshes with the glTF metallic-roughness BSDF (mitsuba_gltf.py, which
    must have been registered: ``mitsuba_gltf.register``)."""
    import mitsuba_gltf

    primitives, doc, blob = mitsuba_gltf.glb_primitives(path)
    shapes = {}
    for j, prim in enumerate(primitives):
        name = f"gltf{index}_{j}"
        ply = _ply(mi, folder, name, prim["vertices"], prim["faces"], prim["normals"], prim["uvs"])
        bsdf = mitsuba_gltf.material_dict(doc, blob, prim["material"], Path(folder))
        shapes[f"object{index}_{j}"] = {"type": "ply", "filename": ply, "bsdf": bsdf,
                                        "face_normals": prim["normals"] is None}  # fmt: skip
    return shapes


def _sunsky(mi, sky: dict) -> dict:
    """Mitsuba's ``sunsky`` for lightprobe's :class:`~lightprobe.emitters.sunsky.SunSky` parameters: its Z-up sky
    stood on +Y (``to_world`` -90 degrees about +X), the sun along the same world direction, and ``complex_sun``
    (the limb-darkened sun lightprobe implements; ../shared/notes/sunsky-mitsuba.md)."""
    from lightprobe.emitters.procedural import sun_direction

    d = sun_direction(sky["sun_elevation"], sky.get("sun_azimuth", 0.0))
    out = {
        "type": "sunsky",
        "turbidity": float(sky.get("turbidity", 3.0)),
        "sun_direction": mi.ScalarVector3f(*map(float, d)),
        "complex_sun": True,
        "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90),
    }
    albedo = sky.get("albedo", 0.3)
    out["albedo"] = float(albedo) if np.ndim(albedo) == 0 else _rgb(albedo)
    for key in ("sun_scale", "sky_scale", "sun_aperture"):
        if key in sky:
            out[key] = float(sky[key])
    return out


def scene_dict(
    mi,
    desc: dict,
    env_file: str | None,
    spp: int,
    folder: str,
    *,
    power_weights: bool = False,
    resolution: tuple[int, int] | None = None,
) -> dict:
    """Mitsuba's scene dictionary for a description of lightprobe.reference_scenes (meshes written to ``folder``).
    ``power_weights``: each area emitter's ``sampling_weight`` is its power, pi A L (of the luminance), so that
    ``direct`` picks emitters in proportion to power, as lightprobe's ``power`` selector does (Mitsuba picks them
    uniformly by default).  ``env_file``: the environment image written as a file (an environment given by a
    ``file`` in the description is read from there); ``resolution``: default the test references' 64 x 48.
    A surface with ``two_sided`` gets Mitsuba's ``twosided`` BSDF (non-emitters only: a shape blocks rays from
    both sides either way); a ``rectangles`` batch becomes one emitting mesh per radiance level; a ``gltf`` object
    its primitives with the glTF metallic-roughness BSDF of mitsuba_gltf.py."""
    from lightprobe.reference_scenes import RESOLUTION

    transform = mi.ScalarTransform4f
    cam = desc["camera"]
    width, height = resolution or RESOLUTION
    d = {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 1},
        "sensor": {
            "type": "perspective",
            "fov": float(cam["fov"]),
            "fov_axis": "x",
            "to_world": transform().look_at(origin=cam["origin"], target=cam["target"], up=[0, 1, 0]),
            "sampler": {"type": "multijitter", "sample_count": spp},
            "film": {
                "type": "hdrfilm",
                "width": width,
                "height": height,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "component_format": "float32",
            },
        },
    }
    env = desc["environment"]
    if env is not None and "file" in env:
        d["environment"] = {"type": "envmap", "filename": env["file"]}
    elif env is not None and "sunsky" in env:
        d["environment"] = _sunsky(mi, env["sunsky"])
    elif env_file is not None:
        d["environment"] = {"type": "envmap", "filename": env_file}
    for i, o in enumerate(desc["objects"]):
        if o["shape"] == "rectangles":
            d |= _window_groups(mi, o, folder, i, power_weights)
            continue
        if o["shape"] == "gltf":
            d |= _gltf_shapes(mi, o["file"], folder, i)
            continue
        bsdf = _bsdf(desc["materials"][o["material"]]) if "material" in o else _black()
        if o.get("two_sided"):
            bsdf = {"type": "twosided", "bsdf": bsdf}
        if o["shape"] == "rectangle":
            origin, u, v = (np.asarray(o[k], dtype=np.float64) for k in ("origin", "edge_u", "edge_v"))
            n = np.cross(u, v)
            n /= np.linalg.norm(n)
            # Mitsuba's rectangle is [-1, 1]^2 in z = 0 with normal +Z
            m = np.eye(4)
            m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u / 2, v / 2, n, origin + (u + v) / 2
            shape = {"type": "rectangle", "to_world": transform(m.tolist()), "bsdf": bsdf}
        elif o["shape"] == "sphere":
            shape = {
                "type": "sphere",
                "center": list(map(float, o["center"])),
                "radius": float(o["radius"]),
                "bsdf": bsdf,
            }
        else:
            ply = _ply(mi, folder, f"mesh{i}", o["vertices"], o["faces"], o.get("normals"))
            shape = {"type": "ply", "filename": ply, "bsdf": bsdf, "face_normals": "normals" not in o}
        if "emission" in o:
            shape["emitter"] = {"type": "area", "radiance": _rgb(o["emission"])}
            if power_weights:
                shape["emitter"]["sampling_weight"] = _power(o)
        d[f"object{i}"] = shape
    return d


def render(name: str, spp: int, passes: int, out: Path, *, lights: int | None = None) -> dict:
    _prefer_llvm19()
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    from lightprobe.images import write_image
    from lightprobe.reference_scenes import describe, environment_image

    desc = describe(name, lights=lights)
    with tempfile.TemporaryDirectory() as tmp:
        image = environment_image(desc)
        env_file = None
        if image is not None:
            env_file = str(Path(tmp) / "env.exr")
            write_image(env_file, image)
        power = name in TEST_SUITE_SCENES  # the occluded building: emitters sampled by power, as the suite's
        scene = mi.load_dict(scene_dict(mi, desc, env_file, spp, tmp, power_weights=power))
        start = time.perf_counter()
        total = total2 = 0.0
        for k in range(passes):
            x = np.array(mi.render(scene, spp=spp, seed=1_000_003 * (k + 1)), dtype=np.float64)
            total = total + x
            total2 = total2 + x * x
        seconds = time.perf_counter() - start
    mean = total / passes
    variance = np.maximum(total2 / passes - mean**2, 0.0) * passes / (passes - 1) / passes
    floor = float(np.mean(variance / (mean**2 + 0.01)))
    settings = {"scene": name, "lights": lights, "spp": spp * passes, "passes": passes}
    settings |= {"sampler": "multijitter", "integrator": "direct", "power_weights": power}
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out, mean=mean.astype(np.float32), variance=variance.astype(np.float32), settings=json.dumps(settings)
    )
    return {**settings, "seconds": round(seconds, 1), "relmse_floor": floor, "out": str(out)}


def main() -> int:
    sys.path.insert(0, str(ROOT / "src"))
    from lightprobe.reference_scenes import NAMES

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=list(NAMES), choices=[*NAMES, *TEST_SUITE_SCENES])
    parser.add_argument("--spp", type=int, default=1024, help="samples per pixel per pass")
    parser.add_argument("--passes", type=int, default=64, help="independent passes (the variance comes from them)")
    parser.add_argument("--out", default=str(ROOT / "tests" / "data"), help="folder for mitsuba_<name>.npz")
    args = parser.parse_args()
    for name in args.scenes:
        print(json.dumps(render(name, args.spp, args.passes, Path(args.out) / f"mitsuba_{name}.npz")), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
