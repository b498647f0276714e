"""Light selectors rendered by the laboratory (``sel:`` strategies, lab/light_render.py) on the suite's scenes: each
one's error and speed, and what the laboratory's estimator costs against the render core's at equal counts.

Per scene (the suite's, 320 x 240; ``reference_scenes.build``) and configuration, ``--seeds`` renders at ``--spp``
samples per pixel, each camera sample one light sample and one BSDF sample (power heuristic, uniform counts):

- ``core bvh``: the render core, ``light_sampler = "bvh"``, no outline control variate (its estimator at these
  counts);
- ``sel:uniform``, ``sel:power``, ``sel:bvh``: lightprobe's selectors through the laboratory's estimator;
- ``sel:PowerOverDistance``: ``examples/light_selectors.py``'s, a user's selector in NumPy.

relMSE without a reference, as ``suite.py --spread`` measures it (decision 124): each pixel's variance between the
seeds' images over (m^2 + 0.01), m the mean of every image of the scene (all unbiased); efficiency 1 / (relMSE x
seconds); seconds the median of the seeds' renders after one that compiles. Printed: one JSON line per row, then a
Markdown table with each selector's efficiency over ``sel:bvh``'s and the core's samples/s over the laboratory's.

    python benchmarks/lab_selectors.py [--scenes area dome building] [--spp 16] [--seeds 2]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

CONFIGS = ("core bvh", "sel:uniform", "sel:power", "sel:bvh", "sel:PowerOverDistance")


def _render(scene, config: str, settings):
    from lightprobe.integrators.wavefront import render
    from lightprobe.lab.render import parse_lab_token, render_lab

    if config == "core bvh":
        return render(scene, dataclasses.replace(settings, light_sampler="bvh"))
    token = (
        config
        if config != "sel:PowerOverDistance"
        else f"sel:{ROOT / 'examples' / 'light_selectors.py'}:PowerOverDistance"
    )
    return render_lab(scene, parse_lab_token(token)[0], settings)


def main() -> int:
    from lightprobe import reference_scenes
    from lightprobe.integrators.settings import RenderSettings
    from suite import _seed_variance

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=["area", "dome", "building"])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--seeds", type=int, default=2)
    args = parser.parse_args()
    rows = []
    for name in args.scenes:
        if (why := reference_scenes.unavailable(name)) is not None:
            print(f"{name}: skipped ({why})", flush=True)
            continue
        scene = reference_scenes.build(name, resolution=reference_scenes.SUITE_RESOLUTION)
        images, seconds = {}, {}
        for config in CONFIGS:
            base = dict(spp=args.spp, n_bsdf=1, n_env=1, lights_per_sample=1, heuristic="power", adaptive=False,
                        outline_control_variate=False)  # fmt: skip
            _render(scene, config, RenderSettings(**base, seed=100))  # compiles
            images[config], seconds[config] = [], []
            for seed in range(1, args.seeds + 1):
                start = time.perf_counter()
                result = _render(scene, config, RenderSettings(**base, seed=seed))
                seconds[config].append(time.perf_counter() - start)
                images[config].append(result.image.astype(np.float64))
        mean = sum(sum(x) for x in images.values()) / sum(len(x) for x in images.values())
        pixels = mean.shape[0] * mean.shape[1]
        for config in CONFIGS:
            relmse = float(np.mean(_seed_variance(images[config]) / (mean * mean + 0.01)))
            s = statistics.median(seconds[config])
            row = {"scene": name, "lights": int(scene.light_table().kind.shape[0]), "config": config, "spp": args.spp,
                   "seconds": s, "samples_per_s": pixels * args.spp / s, "relmse": relmse,
                   "efficiency": 1.0 / (relmse * s), "seeds": args.seeds, "cores": os.cpu_count(),
                   "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}  # fmt: skip
            rows.append(row)
            print(json.dumps(row), flush=True)
    print("\n| scene | lights | " + " | ".join(CONFIGS) + " | core samples/s over sel:bvh's |")
    print("|---|---|" + "---|" * (len(CONFIGS) + 1))
    for name in dict.fromkeys(r["scene"] for r in rows):
        mine = {r["config"]: r for r in rows if r["scene"] == name}
        bvh = mine["sel:bvh"]
        cells = [f"{mine[c]['relmse']:.4g}, {mine[c]['seconds']:.2f} s, "
                 f"{mine[c]['efficiency'] / bvh['efficiency']:.2f}x" for c in CONFIGS]  # fmt: skip
        speed = mine["core bvh"]["samples_per_s"] / bvh["samples_per_s"]
        print(f"| {name} | {bvh['lights']} | " + " | ".join(cells) + f" | {speed:.1f}x |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
