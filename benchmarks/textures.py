"""What textures cost: render speed and memory of a textured glTF asset, with its textures and without.

Writes examples/make_textured_asset.py's asset (the bunny from ../shared/data, else an icosphere) with textures of
``--sizes`` texels (default 1024 and 4096) into a temporary folder, loads it (timing the decode), and renders it
under Blender's courtyard map (a procedural sky without the data) at 640x480 and ``--spp`` samples per pixel:

- ``textured``: as written (base colour, metallic-roughness and normal maps on the bunny, base colour on the ground);
- ``untextured``: the same materials with their textures dropped and each base colour set to its texture's mean.

After a warm-up render (compiling), the two alternate ``--repeats`` times; one JSON line per size and form: load
seconds, texture MiB the kernels hold, render seconds (min and max), camera samples/s, rays/s, peak RSS, cores.

    python benchmarks/textures.py [--spp 32] [--sizes 1024 4096] [--repeats 2]
"""

from __future__ import annotations

import argparse
import copy
import importlib.util
import json
import os
import resource
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _asset_module():
    spec = importlib.util.spec_from_file_location("make_textured_asset", ROOT / "examples" / "make_textured_asset.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _scene(asset, textured: bool, environment):
    from lightprobe.geometry import Camera
    from lightprobe.scene import Scene

    scene = Scene(Camera([0.35, 0.95, 2.3], [0.0, 0.42, 0.0], fov=32, resolution=(640, 480)), environment)
    for item in asset.meshes:
        material = item.material
        if not textured:
            material = copy.copy(material)
            if material.textures is not None and material.textures.base_color is not None:
                mean = material.textures.base_color.mean_rgb(srgb=True)
                material = type(material)(material.base_color * mean, material.metallic, material.roughness)
            else:
                material = type(material)(material.base_color, material.metallic, material.roughness)
        scene.add(item.mesh, material, two_sided=item.two_sided, name=item.name)
    return scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 4096])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()

    from lightprobe.data import data_dir
    from lightprobe.emitters.envmap import EnvironmentMap
    from lightprobe.emitters.procedural import sky_with_sun
    from lightprobe.integrators import RenderSettings, render
    from lightprobe.io.gltf import load_gltf

    root = data_dir()
    courtyard = root / "envmaps" / "blender_courtyard.exr" if root else None
    if courtyard is not None and courtyard.exists():
        environment, light = EnvironmentMap.load(courtyard, rotation=40.0), "blender_courtyard.exr"
    else:
        environment, light = EnvironmentMap.from_array(sky_with_sun(512, 256)), "procedural sky"
    module = _asset_module()
    work = Path(tempfile.mkdtemp(prefix="lightprobe-textures-bench-"))
    settings = RenderSettings(spp=args.spp, seed=1)
    for size in args.sizes:
        path = module.main(work / f"asset{size}.glb", size=size)
        start = time.perf_counter()
        asset = load_gltf(path)
        load_seconds = time.perf_counter() - start
        scenes = {"textured": _scene(asset, True, environment), "untextured": _scene(asset, False, environment)}
        render(scenes["textured"], RenderSettings(spp=1))  # compile / warm up
        times: dict[str, list[float]] = {name: [] for name in scenes}
        rays: dict[str, float] = {}
        for _ in range(args.repeats):
            for name, scene in scenes.items():
                result = render(scene, settings)
                times[name].append(result.stats["seconds"])
                rays[name] = result.stats["camera_rays"] + result.stats["shadow_rays"]
        for name, scene in scenes.items():
            best = min(times[name])
            samples = 640 * 480 * args.spp
            print(
                json.dumps(
                    {
                        "form": name,
                        "texture_size": size,
                        "light": light,
                        "triangles": scene.triangle_count,
                        "spp": args.spp,
                        "glb_mb": round(path.stat().st_size / 2**20, 1),
                        "load_s": round(load_seconds, 2),
                        "texture_mib": round(scene.texture_bytes / 2**20, 1),
                        "seconds_min": round(best, 2),
                        "seconds_max": round(max(times[name]), 2),
                        "samples_per_s": round(samples / best),
                        "rays_per_s": round(rays[name] / best) if rays[name] else None,
                        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
                        "cores": os.cpu_count(),
                    }
                ),
                flush=True,
            )


if __name__ == "__main__":
    main()
