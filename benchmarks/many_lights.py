#!/usr/bin/env python3
"""Benchmark: the cost of light selection as the number of lights grows.

    python benchmarks/many_lights.py                        # 1k, 10k, 100k lights x uniform, power, bvh
    python benchmarks/many_lights.py --lights 1000 --plot many_lights.png

Renders the built-in many-light scene (``lightprobe render --demo many-lights``, the panels' count changed) with
light sampling only (K = 16 lights per camera sample, N = 1, no BSDF samples) and prints one JSON line per
configuration: lights, selector, seconds (render loop after warm-up), samples_per_s (camera samples), rays_per_s
(camera + shadow rays), setup_seconds (scene, light table, selector and BVH build, kernel load), peak_mb, cores.
With --plot, a log-log figure of seconds against the number of lights.  The cost of ``uniform`` and ``power`` per
pick is O(1) and O(log n); ``bvh`` is O(depth) = O(log n) per pick plus O(depth) per MIS pmf.
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
    return {
        "lights": n_lights,
        "selector": selector,
        "spp": spp,
        "width": width,
        "seconds": round(stats["seconds"], 4),
        "samples_per_s": round(stats["samples_per_s"]),
        "rays_per_s": round(stats["rays_per_s"]),
        "setup_seconds": round(time.perf_counter() - start - stats["seconds"], 3),
        "peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "cores": os.cpu_count(),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lights", type=int, nargs="*", default=[1000, 10000, 100000])
    parser.add_argument("--selectors", nargs="*", default=["uniform", "power", "bvh"])
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--width", type=int, default=240)
    parser.add_argument("--plot", help="write a log-log PNG of seconds against lights")
    args = parser.parse_args()
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
