"""The light picks a probe chooses (integrators/picks.py, decisions.md 123) against K = 4 and issue 59's baseline.

On the suite's scenes of 64 bounded lights or more (the ones the probe applies to), at 16, 64 and 256 spp, each
configuration rendered with seeds 20-23 at 320 x 240, interleaved (every configuration's render of one seed before
the next seed):

- ``default``: lightprobe's defaults (a render too short for the probe, ``picks.PROBE_SHARE``: K = 4);
- ``probe``: the defaults with the probe however short the render (``picks.PROBE_SHARE`` = 1e9), which shows what
  the probe would give and cost below its threshold;
- ``K=4``: the defaults with ``lights_per_sample = 4`` (the choice before the probe, decision 118);
- ``bvh``: issue 59's baseline, the light BVH, K = 2 and no outline control variate.

No reference is needed: every configuration is unbiased (each is z-tested against analytic answers and Mitsuba's
references in tests/), so its MSE is its variance, measured from the spread between seeds: half the squared
difference of the renders of seeds 20 and 21, and of 22 and 23, over (ref^2 + 0.01), where ``ref`` is the mean of
every render of the scene weighted by its samples.  Efficiency = 1 / (relMSE x seconds), the seconds the median of
the render's own (probe included, setup and compiling not).

With ``--mitsuba`` (the ``peers`` extra), Mitsuba 3's ``direct`` integrator renders the same seeds at the same
spp in the suite's configurations for many lights: each of its samplers, 1 + 1 and 4 + 4 samples, emitters
weighted uniformly and by power; timed around ``mi.render`` after a compiling render.  Its relMSE is measured the
same way, against the same mean (both renderers are z-tested against each other), and each lightprobe row also
says its efficiency over Mitsuba's best configuration.

    python benchmarks/light_picks.py [--scenes building dome ceiling city] [--spp 16 64 256] [--mitsuba]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from lightprobe import reference_scenes
from lightprobe.integrators import picks
from lightprobe.integrators.settings import RenderSettings
from lightprobe.integrators.wavefront import render

SCENES = ("building", "dome", "ceiling", "city")
SEEDS = (20, 21, 22, 23)
CONFIGS = {
    "default": {},
    "probe": {},  # picks.PROBE_SHARE raised for it
    "K=4": {"lights_per_sample": 4},
    "bvh": {"light_sampler": "bvh", "lights_per_sample": 2, "outline_control_variate": False},
}


def _render(scene, spp: int, seed: int, config: str):
    settings = RenderSettings(spp=spp, seed=seed, **CONFIGS[config])
    saved = picks.PROBE_SHARE
    picks.PROBE_SHARE = 1e9 if config == "probe" else saved
    try:
        result = render(scene, settings)
    finally:
        picks.PROBE_SHARE = saved
    chosen = result.stats["lights_per_sample"]
    return result.image.astype(np.float64), result.stats["seconds"], chosen, "picks_probe" in result.stats


def _mitsuba_runs(name: str, resolution, spp: int) -> dict:
    """{configuration: [(image, seconds), ...]} of Mitsuba's renders of suite scene ``name`` at ``spp``."""
    import tempfile

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import suite

    mi, mr = suite._mitsuba()
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for power in (False, True):
            d = suite._mitsuba_scene(mi, mr, name, resolution, tmp, power=power, spp=spp)
            scene = mi.load_dict(d)
            for sampler in suite.MITSUBA_SAMPLERS:
                sensor = suite._sensor(mi, d, sampler, spp)
                for n in (1, 4):
                    integrator = suite._integrator(mi, n)
                    mi.render(scene, sensor=sensor, integrator=integrator, spp=spp, seed=10_000)  # compiles
                    config = f"mitsuba {sampler} {n}+{n}" + (" power" if power else "")
                    for seed in SEEDS:
                        start = time.perf_counter()
                        image = mi.render(scene, sensor=sensor, integrator=integrator, spp=spp, seed=seed)
                        x = np.array(image, dtype=np.float64)
                        runs.setdefault(config, []).append((x, time.perf_counter() - start))
    return runs


def _row(images: list, seconds: list, ref: np.ndarray) -> dict:
    """relMSE from the spread between seeds (pairs 0-1, 2-3), the median seconds and the efficiency."""
    pairs = [(images[i], images[i + 1]) for i in range(0, len(images) - 1, 2)]
    variance = np.mean([0.5 * (a - b) ** 2 for a, b in pairs], axis=0)
    relmse = float(np.mean(variance / (ref * ref + 0.01)))
    median = float(np.median(seconds))
    return {"relmse": relmse, "seconds": median, "efficiency": 1.0 / (relmse * median)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--spp", nargs="+", type=int, default=[16, 64, 256])
    parser.add_argument("--resolution", nargs=2, type=int, default=[320, 240])
    parser.add_argument("--mitsuba", action="store_true", help="Mitsuba 3 too (the peers extra)")
    args = parser.parse_args()
    print(json.dumps({"cores": os.cpu_count(), "resolution": args.resolution, "seeds": SEEDS}), flush=True)
    for name in args.scenes:
        if (why := reference_scenes.unavailable(name)) is not None:
            print(f"{name}: skipped ({why})")
            continue
        scene = reference_scenes.build(name, resolution=tuple(args.resolution))
        render(scene, RenderSettings(spp=4, seed=10_000))  # compiles (and loads) the stages: not timed
        runs = {}
        for spp in args.spp:
            for seed in SEEDS:
                for config in CONFIGS:
                    if config == "probe" and (spp, "default") in runs and runs[spp, "default"][-1][3]:
                        continue  # the default probed: the same
                    runs.setdefault((spp, config), []).append(_render(scene, spp, seed, config))
        total = sum(spp * image for (spp, _), rs in runs.items() for image, *_ in rs)
        ref = total / sum(spp * len(rs) for (spp, _), rs in runs.items())
        rows = {}
        for (spp, config), rs in runs.items():
            rows[spp, config] = {**_row([r[0] for r in rs], [r[1] for r in rs], ref), "K": sorted({r[2] for r in rs})}
        best = {}
        for spp in args.spp if args.mitsuba else ():
            for config, rs in _mitsuba_runs(name, args.resolution, spp).items():
                row = _row([r[0] for r in rs], [r[1] for r in rs], ref)
                print(json.dumps({"scene": name, "spp": spp, "config": config, **row}), flush=True)
                best[spp] = max(best.get(spp, 0.0), row["efficiency"])
        for (spp, config), row in rows.items():
            base, k4 = rows[spp, "bvh"]["efficiency"], rows[spp, "K=4"]["efficiency"]
            ratios = {"over_bvh": row["efficiency"] / base, "over_K4": row["efficiency"] / k4}
            if spp in best:
                ratios["over_mitsuba_best"] = row["efficiency"] / best[spp]
            print(json.dumps({"scene": name, "spp": spp, "config": config, **row, **ratios}), flush=True)


if __name__ == "__main__":
    main()
