#!/usr/bin/env python3
"""Benchmark: many lights -- the cost of light selection as the lights grow, and thousands of lights from a file.

    python benchmarks/many_lights.py                        # 1k, 10k, 100k lights x uniform, power, bvh
    python benchmarks/many_lights.py --lights 1000 --plot many_lights.png
    python benchmarks/many_lights.py --scene-file 2000 20000 100000     # rectangles in a scene file vs one mesh

Selection: renders the built-in many-light scene (``lightprobe render --demo many-lights``, the panels' count
changed) with light sampling only (K = 16 lights per camera sample, N = 1, no BSDF samples) and prints one JSON line
per configuration: lights, selector, seconds (render loop after warm-up), samples_per_s (camera samples), rays_per_s
(camera + shadow rays), setup_seconds (scene, light table, selector and BVH build, kernel load), bvh_seconds (with
``bvh``: the light hierarchy's build again, alone), peak_mb, cores.
With --plot, a log-log figure of seconds against the number of lights.  The cost of ``uniform`` and ``power`` per
pick is O(1) and O(log n); ``bvh`` is O(depth) = O(log n) per pick plus O(depth) per MIS pmf.

Scene files (``--scene-file N ...``): writes a TOML scene with N rectangle lights as ``[[objects]]`` (quads over the
demo's blob, sphere and ground, powers over four decades) and the same quads as one PLY mesh with per-face
emission (``face_emission = "lights.npy"``), then for each: load_seconds (reading the file into a Scene),
setup_seconds (arrays, shape and light hierarchies, kernel load), seconds (render, default settings: MIS, the
default light selector), samples_per_s and peak_mb (this process's peak resident memory so far), and their ratio.
Each form renders in a process of its own (so that peak memory is its own).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time


def run(n_lights: int, selector: str, spp: int, width: int) -> dict:
    from lightprobe.demo import many_lights_scene
    from lightprobe.integrators.wavefront import RenderSettings, render

    start = time.perf_counter()
    scene = many_lights_scene(n_lights, resolution=(width, width * 2 // 3))
    settings = RenderSettings(spp=spp, strategy="env", n_bsdf=0, n_env=1, lights_per_sample=16, light_sampler=selector)
    result = render(scene, settings)
    stats = result.stats
    bvh_seconds = None
    if selector == "bvh":  # the light hierarchy's build alone, compiled and warm (the target: <= 0.5 s)
        from lightprobe.emitters.selection import build_selector

        table = scene.light_table()
        start_bvh = time.perf_counter()
        build_selector("bvh", table)
        bvh_seconds = round(time.perf_counter() - start_bvh, 3)
    return {
        "lights": n_lights,
        "selector": selector,
        "spp": spp,
        "width": width,
        "seconds": round(stats["seconds"], 4),
        "samples_per_s": round(stats["samples_per_s"]),
        "rays_per_s": round(stats["rays_per_s"]),
        "setup_seconds": round(time.perf_counter() - start - stats["seconds"] - (bvh_seconds or 0.0), 3),
        "bvh_seconds": bvh_seconds,
        "peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "cores": os.cpu_count(),
    }


def _quads(n: int, seed: int = 3, extent: float = 6.0):
    """n square lights facing down over an ``extent`` square 2.1-2.7 m up: corners, edges, radiances (n, 3)."""
    import math

    import numpy as np

    rng = np.random.default_rng(seed)
    centres = np.column_stack(
        [
            rng.uniform(-extent / 2, extent / 2, n),
            2.4 + rng.uniform(-0.3, 0.3, n),
            rng.uniform(-extent / 2, extent / 2, n),
        ]
    )
    size = 0.35 * extent / math.sqrt(n)
    angle = rng.uniform(0, 2 * math.pi, n)
    ex = size * np.column_stack([np.cos(angle), np.zeros(n), np.sin(angle)])
    ez = size * np.column_stack([-np.sin(angle), np.zeros(n), np.cos(angle)])  # ex x ez = -Y: facing down
    level = 10.0 ** rng.uniform(-1.0, 3.0, n) * 3.0 / math.sqrt(n)
    return centres - (ex + ez) / 2, ex, ez, np.column_stack([level, 0.8 * level, 0.6 * level])


_SCENE_HEAD = """[camera]
origin = [0.0, 1.2, 7.0]
target = [0.0, 1.0, 0.0]
fov = 45.0
resolution = [{width}, {height}]

[materials.ground]
type = "lambert"
albedo = 0.5
[materials.aluminium]
type = "conductor"
alpha = 0.2
material = "Al"

[[objects]]
type = "ground"
size = 40.0
material = "ground"

[[objects]]
type = "sphere"
center = [-1.75, 0.6, 0.7]
radius = 0.6
material = "aluminium"
"""


def write_scene_files(n: int, folder, width: int) -> tuple:
    """(rectangles.toml, mesh.toml) in ``folder``: the same n quads as rectangle objects and as one PLY mesh with
    per-face emission."""
    from pathlib import Path

    import numpy as np
    import trimesh

    folder = Path(folder)
    corner, u, v, radiance = _quads(n)
    head = _SCENE_HEAD.format(width=width, height=width * 3 // 4)
    f3 = lambda a: "[" + ", ".join(f"{x:.9g}" for x in a) + "]"  # noqa: E731
    lines = [head]
    for i in range(n):
        lines.append(
            f'[[objects]]\ntype = "rectangle"\norigin = {f3(corner[i])}\nedge_u = {f3(u[i])}\n'
            f"edge_v = {f3(v[i])}\nemission = {f3(radiance[i])}\n"
        )
    rects = folder / f"rectangles_{n}.toml"
    rects.write_text("\n".join(lines))
    vertices = np.concatenate([corner, corner + u, corner + u + v, corner + v], axis=1).reshape(-1, 3)
    base = 4 * np.arange(n)[:, None]
    faces = (base + np.array([0, 1, 2, 0, 2, 3])).reshape(-1, 3)
    trimesh.Trimesh(vertices, faces, process=False).export(folder / f"lights_{n}.ply")
    np.save(folder / f"lights_{n}.npy", np.repeat(radiance, 2, axis=0))
    mesh = folder / f"mesh_{n}.toml"
    mesh.write_text(
        head + f'\n[[objects]]\ntype = "mesh"\nfile = "lights_{n}.ply"\nsmooth = false\n'
        f'face_emission = "lights_{n}.npy"\n'
    )
    return rects, mesh


def run_scene_file(path: str, spp: int) -> dict:
    """Load and render one scene file (in this process): the figures of the module docstring."""
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.io.scene_file import load_scene

    start = time.perf_counter()
    scene, _ = load_scene(path)
    load = time.perf_counter() - start
    start = time.perf_counter()
    result = render(scene, RenderSettings(spp=spp))
    stats = result.stats
    return {
        "file": os.path.basename(path),
        "lights": stats["area_lights"],
        "spp": spp,
        "load_seconds": round(load, 3),
        "setup_seconds": round(time.perf_counter() - start - stats["seconds"], 3),
        "seconds": round(stats["seconds"], 3),
        "samples_per_s": round(stats["samples_per_s"]),
        "peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "cores": os.cpu_count(),
    }


def scene_files(counts, spp: int, width: int) -> None:
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        for n in counts:
            rects, mesh = write_scene_files(n, folder, width)
            rows = {}
            for form, path in (("mesh", mesh), ("rectangles", rects)):
                out = subprocess.run(
                    [sys.executable, __file__, "--run-scene-file", str(path), "--spp", str(spp)],
                    capture_output=True,
                    text=True,
                    check=True,
                )
                rows[form] = json.loads(out.stdout.strip().splitlines()[-1])
                print(json.dumps({"form": form, **rows[form]}), flush=True)
            ratio = rows["rectangles"]["seconds"] / rows["mesh"]["seconds"]
            print(json.dumps({"lights": n, "rectangles_over_mesh_seconds": round(ratio, 2)}), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene-file", type=int, nargs="*", help="rectangle lights per scene file (see above)")
    parser.add_argument("--run-scene-file", help=argparse.SUPPRESS)
    parser.add_argument("--lights", type=int, nargs="*", default=[1000, 10000, 100000])
    parser.add_argument("--selectors", nargs="*", default=["uniform", "power", "bvh"])
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--width", type=int, default=240)
    parser.add_argument("--plot", help="write a log-log PNG of seconds against lights")
    args = parser.parse_args()
    if args.run_scene_file:
        print(json.dumps(run_scene_file(args.run_scene_file, args.spp)))
        return 0
    if args.scene_file:
        scene_files(args.scene_file, args.spp, args.width)
        return 0
    rows = []
    for n in args.lights:
        for selector in args.selectors:
            row = run(n, selector, args.spp, args.width)
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5.5, 4))
        for selector in args.selectors:
            mine = [r for r in rows if r["selector"] == selector]
            ax.loglog([r["lights"] for r in mine], [r["seconds"] for r in mine], "o-", label=selector)
        ax.set_xlabel("lights")
        ax.set_ylabel(f"seconds ({args.width} px wide, {args.spp} spp, K = 16)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.plot, dpi=110)
        print(f"wrote {args.plot}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
