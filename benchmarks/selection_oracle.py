#!/usr/bin/env python3
"""How far each light selector is from the oracle, where the default render's variance comes from, and what
resampling the light sample (RIS) could give, on the suite's scenes (issue 59, items 2 and 3).

    python benchmarks/selection_oracle.py                          # building, area, many, ceiling, dome, glossy
    python benchmarks/selection_oracle.py --scenes building --candidates 1 2 4 8 16 32

Per scene, from ``lightprobe.experiments.light_choice`` (what ``compare``'s report shows): every selector's
light-sample variance over the oracle's (lightprobe's uniform, power, bvh; the selection a 64-spp
``light_sampler = "learned"`` render learned; the unoccluded oracle, the oracle, the variance-optimal choice), and
the default strategy's one-sample variance split into the choice of light, the point on it, visibility, the BSDF
sample and the pixel.

RIS: resampled importance sampling of the light sample over M candidates drawn as today (a BVH pick, then the light's
own sampling), the target the unshadowed contribution lum(f L cos): one candidate kept in proportion to its weight
w = target / (pmf p), the estimate V f L cos / target x mean(w) (Talbot et al. 2005), unbiased for any M.  Its
variance is simulated at the same shading points from the brute-force tables (``--trials`` RIS draws a point), light
sampling alone.  What M candidates cost is measured: a render of the default strategy's ``light_samples`` stage time
per light sample (a pick and a light sample) plus its ``finish`` stage time per slot (the BSDF evaluation a
candidate's target needs); the predicted efficiency against M = 1 is then

    (V_light(1) + V_rest) T / ((V_light(M) + V_rest) (T + (M - 1) n_light t_candidate))

with V_rest the split's BSDF and pixel terms and T the render's seconds per camera sample: an upper bound under MIS,
whose weights, taken from the source density, give resampled samples less (decisions.md 24).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

SCENES = ("building", "area", "many", "ceiling", "dome", "glossy")


def ris_variance(g, seen, pmf, weight, m: int, trials: int, rng) -> float:
    """The weighted mean over the points of the RIS estimator's variance / (mean^2 + 0.01), M = ``m`` candidates
    from ``pmf`` (then a uniform pick among a light's samples)."""
    n_points, n_lights, k = g.shape
    truth = np.where(seen, g, 0.0).mean(axis=2).sum(axis=1)
    out = np.zeros(n_points)
    for i in range(n_points):
        if truth[i] <= 0.0:
            continue
        cdf = np.cumsum(pmf[i])
        light = np.minimum(np.searchsorted(cdf / cdf[-1], rng.random((trials, m)), side="right"), n_lights - 1)
        sample = rng.integers(0, k, (trials, m))
        w = g[i, light, sample] / pmf[i][light]
        total = w.sum(axis=1)
        kept = np.minimum((np.cumsum(w, axis=1) < (rng.random(trials) * total)[:, None]).sum(axis=1), m - 1)
        estimate = np.where(total > 0.0, seen[i, light, sample][np.arange(trials), kept] * total / m, 0.0)
        out[i] = estimate.var() / (truth[i] ** 2 + 0.01)
    return float(np.sum(weight * out))


def candidate_cost(scene_name: str, spp: int) -> tuple[float, float, int]:
    """(seconds per camera sample, seconds per RIS candidate, light samples per camera sample) of a default render."""
    from lightprobe.integrators import wavefront
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.reference_scenes import build

    settings = RenderSettings(spp=spp, adaptive=False, seed=1)
    render(build(scene_name), RenderSettings(spp=1, adaptive=False))  # compiled and warm
    wavefront.PROFILE = {}
    try:
        result = render(build(scene_name), settings)
        profile = dict(wavefront.PROFILE)
    finally:
        wavefront.PROFILE = None
    stats = result.stats
    samples = result.counts.size * spp
    n_light, n_bsdf = stats["lights_per_sample"] * stats["n_env"], stats["n_bsdf"]
    per_candidate = profile.get("light_samples", 0.0) / (samples * n_light) + profile.get("finish", 0.0) / (
        samples * (n_light + n_bsdf)
    )
    return stats["seconds"] / samples, per_candidate, n_light


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--points", type=int, default=512, help="camera samples measured (4 a pixel)")
    parser.add_argument("--learn-spp", type=int, default=64, help="the render whose learning is measured")
    parser.add_argument("--candidates", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    parser.add_argument("--trials", type=int, default=4000, help="RIS draws at each point")
    parser.add_argument("--cost-spp", type=int, default=16, help="the render that times a candidate")
    args = parser.parse_args()
    warnings.filterwarnings("ignore", module="numba")
    from lightprobe.experiments.light_choice import measure
    from lightprobe.integrators.wavefront import RenderSettings, render, settings_for
    from lightprobe.reference_scenes import build

    for name in args.scenes:
        start = time.perf_counter()
        learned = render(build(name), RenderSettings(spp=args.learn_spp, light_sampler="learned", seed=3))
        scene = build(name)
        strategies = [
            ("mis", settings_for(scene, RenderSettings(adaptive=False)), None),
            ("learned", settings_for(scene, RenderSettings(adaptive=False, light_sampler="learned")),
             learned.accumulator.learned),
        ]  # fmt: skip
        found = measure(scene, strategies, points=args.points, keep_tables=True)
        if found is None or found.skipped:
            print(f"{name}: not measured ({'fewer than two lights' if found is None else found.skipped})")
            continue
        print(f"== {name}: {found.points} points, {found.lights} lights, {found.per_light} samples a light, "
              f"{100 * found.arriving:.1f} % of the unoccluded light arrives ({found.seconds:.1f} s)")  # fmt: skip
        for row in found.selectors:
            print(f"  {row.name:42s} choice {row.choice:10.4g}  light sample {row.total:10.4g}  "
                  f"x oracle {row.vs_oracle:9.3g}")  # fmt: skip
        for split in found.splits:
            parts = {k: getattr(split, k) for k in ("choice", "point", "visibility", "bsdf", "pixel")}
            shares = "  ".join(f"{k} {100 * v / split.total:5.1f} %" for k, v in parts.items())
            print(f"  split {split.label:8s} [{split.selector}] {shares}  one-sample relMSE {split.total:.4g}")
        tables, default = found.tables, found.splits[0]
        rng = np.random.default_rng(1)
        ris = {m: ris_variance(tables["g"], tables["seen"], tables["pmfs"]["bvh"], tables["weight"], m, args.trials,
                               rng) for m in args.candidates}  # fmt: skip
        seconds, per_candidate, n_light = candidate_cost(name, args.cost_spp)
        light = default.choice + default.point + default.visibility
        rest = default.bsdf + default.pixel
        print(f"  RIS over BVH candidates (light sampling alone; a candidate {1e9 * per_candidate:.0f} ns, a camera "
              f"sample {1e9 * seconds:.0f} ns, {n_light} light samples each):")  # fmt: skip
        for m, v in ris.items():
            scale = v / ris[args.candidates[0]]
            cost = (seconds + (m - 1) * n_light * per_candidate) / seconds
            efficiency = (light + rest) / (light * scale + rest) / cost
            print(f"    M = {m:3d}: light-sample variance {v:9.4g} ({scale:6.3f} of M = 1), time x {cost:5.2f}, "
                  f"predicted efficiency x {efficiency:5.2f}")  # fmt: skip
        print(f"  ({time.perf_counter() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
