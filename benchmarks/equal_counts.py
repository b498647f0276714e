#!/usr/bin/env python3
"""The time of a camera sample at Mitsuba 3's counts: one light sample and one BSDF sample, lightprobe against
Mitsuba's ``direct`` integrator with ``emitter_samples = bsdf_samples = 1`` (issue 57, item 2).

    python benchmarks/equal_counts.py                         # area, glossy, ceiling, dome, building, city
    python benchmarks/equal_counts.py --scenes city --spp 64 --repeats 5

lightprobe: ``n_bsdf = 1``, ``lights_per_sample = 1``, uniform counts, no outline control variate, with each light
selector asked for (``--selectors``, default ``bvh`` and ``power``: Mitsuba picks by power on the many-light scenes
and uniformly elsewhere); the stage profile (``wavefront.PROFILE``) of its fastest render. Mitsuba: its ``llvm``
variant, each sampler of the suite, uniform and power-weighted emitters, the fastest. Each figure is the fastest of
``--repeats`` renders after one that compiles; ns per camera sample = seconds / (pixels x spp), on this machine's
cores (the core count is printed). No reference is needed: this measures time, not error (the suite's table has
both). Needs the ``peers`` extra for the Mitsuba column (without it, lightprobe's alone).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "src"))

SCENES = ("area", "glossy", "ceiling", "dome", "building", "city")


def lightprobe_times(scene_name: str, resolution, spp: int, repeats: int, selector: str, threads: int | None):
    """(fastest seconds, that render's stage profile in seconds) at one light + one BSDF sample."""
    from lightprobe.integrators import wavefront
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.reference_scenes import build

    scene = build(scene_name, resolution=tuple(resolution))
    options = dict(n_bsdf=1, lights_per_sample=1, adaptive=False, outline_control_variate=False,
                   light_sampler=selector, threads=threads)  # fmt: skip
    render(scene, RenderSettings(spp=4, seed=10_000, **options))  # compile
    best, profile = float("inf"), {}
    for r in range(repeats):
        wavefront.PROFILE = {}
        result = render(scene, RenderSettings(spp=spp, seed=r + 1, **options))
        seconds = result.stats["seconds"]
        if seconds < best:
            best, profile = seconds, dict(wavefront.PROFILE)
    wavefront.PROFILE = None
    return best, profile


def mitsuba_times(scene_name: str, resolution, spp: int, repeats: int) -> dict[str, float]:
    """Fastest seconds of each Mitsuba configuration (sampler, power weights) at 1 + 1."""
    import suite

    mi, mr = suite._mitsuba()
    times = {}
    # the peer kit's assets are made once into the suite's cache, as suite.py does
    cache = Path(os.environ.setdefault("LIGHTPROBE_SUITE_CACHE", str(Path.home() / ".cache" / "lightprobe-suite")))
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for power in (False, True) if scene_name in suite.MANY_LIGHTS else (False,):
            d = suite._mitsuba_scene(mi, mr, scene_name, resolution, tmp, power=power, spp=spp)
            scene = mi.load_dict(d)
            integrator = suite._integrator(mi, 1)
            for sampler in suite.MITSUBA_SAMPLERS:
                sensor = suite._sensor(mi, d, sampler, spp)
                mi.render(scene, sensor=sensor, integrator=integrator, spp=spp, seed=10_000)  # compile
                best = float("inf")
                for s in range(repeats):
                    begin = time.perf_counter()
                    image = mi.render(scene, sensor=sensor, integrator=integrator, spp=spp, seed=s + 1)
                    image.numpy()  # wait for the kernel
                    best = min(best, time.perf_counter() - begin)
                times[f"{sampler}" + (" power" if power else "")] = best
    return times


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--resolution", type=int, nargs=2, default=[320, 240])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--selectors", nargs="*", default=["bvh", "power"])
    parser.add_argument("--threads", type=int, default=None, help="lightprobe's threads [all cores]")
    parser.add_argument("--no-mitsuba", action="store_true")
    args = parser.parse_args()
    from lightprobe.reference_scenes import SUITE, unavailable

    unknown = [s for s in args.scenes if s not in SUITE]
    if unknown:
        print(f"equal_counts.py: unknown scene {unknown[0]!r} (the suite's: {', '.join(SUITE)})", file=sys.stderr)
        return 2
    try:
        import mitsuba  # noqa: F401

        have_mitsuba = not args.no_mitsuba
    except ImportError:
        have_mitsuba = False
        print("Mitsuba 3 is not installed (pip install -e '.[peers]'): lightprobe's column alone", file=sys.stderr)
    samples = args.resolution[0] * args.resolution[1] * args.spp
    print(json.dumps({"cores": os.cpu_count(), "spp": args.spp, "resolution": args.resolution}), flush=True)
    rows = []
    for name in args.scenes:
        why = unavailable(name)
        if why is not None:
            print(json.dumps({"scene": name, "skipped": why}), flush=True)
            continue
        row = {"scene": name}
        for selector in args.selectors:
            seconds, profile = lightprobe_times(name, args.resolution, args.spp, args.repeats, selector, args.threads)
            row[f"lp {selector} ns"] = round(1e9 * seconds / samples, 1)
            stages = sorted(profile.items(), key=lambda kv: -kv[1])[:4]
            row[f"lp {selector} stages ns"] = {k: round(1e9 * v / samples, 1) for k, v in stages}
        if have_mitsuba:
            times = mitsuba_times(name, args.resolution, args.spp, args.repeats)
            config, seconds = min(times.items(), key=lambda kv: kv[1])
            row["mitsuba ns"] = round(1e9 * seconds / samples, 1)
            row["mitsuba config"] = config
            for selector in args.selectors:
                row[f"ratio {selector}"] = round(row[f"lp {selector} ns"] / row["mitsuba ns"], 2)
        rows.append(row)
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
