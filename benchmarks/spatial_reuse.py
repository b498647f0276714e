#!/usr/bin/env python3
"""Spatial reuse of light samples between neighbouring pixels (ReSTIR's spatial pass, Bitterli et al. 2020, with
the generalised balance heuristic's unbiased weights, Lin et al. 2022), measured against the light BVH's samples
and resampling within a pixel (issue 59, item 2; decision 126).

Light sampling alone, of the bounded lights (area lights: rectangles, triangles, spheres; an infinite light's pick
gives nothing here, in every estimator alike), one camera sample per pixel and pass, all estimators on the same
shading points of each pass, each with ONE shadow ray per pixel and pass unless said:

- ``bvh``: a BVH pick and a point on its light: f L V G / (P(l) p(x | l)) (area measure);
- ``bvh x2``, ``bvh x4``: two and four such samples, averaged (2 and 4 shadow rays);
- ``ris M``: M such candidates, one kept in proportion to target / source, the target the unshadowed
  contribution p^(x) = lum(f L G) (Talbot et al. 2005): f L V G (y) W, W = mean(p^ / q) / p^(y);
- ``reuse M, k``: each pixel's ``ris M`` reservoir, then k neighbours' reservoirs (random pixels within ``RADIUS``
  pixels, drawn per pass) resampled at the pixel: candidate j weighed m_j(y_j) p^_i(y_j) W_j, with
  m_j(y) = p^_j(y) / sum_t p^_t(y) over the pixel and its neighbours (each domain's target at the sample: (k + 1)^2
  target evaluations a pixel), the kept y's W = sum of the weights / p^_i(y); the sample reconnects to the same point
  on the light, so in area measure there is no Jacobian.

Each estimator's relMSE per pass: each pixel's variance over ``--spp`` passes / (m^2 + 0.01), m the mean of every
estimator's image (all unbiased for the same image: the pooled z of each against ``bvh x4`` says so). The cost
beside it: candidates (light samples with their BVH pick), target evaluations and shadow rays per camera sample,
and the compiled kernels' seconds per candidate and per target evaluation measured here; the predicted efficiency
against ``bvh`` takes a camera sample's time in a default render (decisions.md 116's profile) plus what the extra
candidates, evaluations and shadow rays cost (``SHADOW_NS`` each), with the light-sample variance alone (the BSDF
and pixel terms left out: an upper bound on any gain).

    python benchmarks/spatial_reuse.py [--scenes dome building ceiling many] [--spp 16]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit, prange

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from lightprobe.bsdfs.dispatch import bsdf_eval  # noqa: E402
from lightprobe.emitters.area import STRATEGIES as LIGHT_STRATEGIES  # noqa: E402
from lightprobe.emitters.lights import emitted, light_normal, light_sample_of  # noqa: E402
from lightprobe.geometry.frame import to_local  # noqa: E402
from lightprobe.geometry.intersect import ray_offset  # noqa: E402
from lightprobe.integrators.stages.shadows import ray_to_light  # noqa: E402

#: neighbours are drawn uniformly within this many pixels
RADIUS = 10.0
#: a camera sample's seconds in a default render and a candidate's (decisions.md 116: the light-sample stage per
#: light sample plus the finish stage per slot), per scene
COSTS_NS = {"building": (666, 199), "area": (445, 86), "many": (521, 137), "ceiling": (598, 158), "dome": (506, 124)}
#: a shadow ray's nanoseconds in a render (performance.md, "A camera sample at Mitsuba's counts": the shadow stages
#: took 39-50 ns a camera sample of one light sample on the dome and the ceiling)
SHADOW_NS = 50.0
#: the light sampling strategy of a default render (solid angle, small lights by area: decision 119)
STRATEGY = LIGHT_STRATEGIES["solid-angle"]


@njit(cache=False)
def _target(lights, kinds, params, point, frame, wo, material, i, light, x, y, z):
    """Pixel i's unshadowed contribution from the point (x, y, z) on ``light``, in area measure: (f L G rgb, p^)."""
    dx, dy, dz = x - point[i, 0], y - point[i, 1], z - point[i, 2]
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    d = math.sqrt(d2)
    wx, wy, wz = dx / d, dy / d, dz / d
    wi = to_local(frame[i, 0:3], frame[i, 3:6], frame[i, 6:9], wx, wy, wz)
    if wi[2] <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    n = light_normal(lights, light, x, y, z)
    cos_l = abs(n[0] * wx + n[1] * wy + n[2] * wz)
    lr, lg, lb = emitted(lights, light, x, y, z, wx, wy, wz)
    m = material[i]
    f = bsdf_eval(kinds[m], params[m], (wo[i, 0], wo[i, 1], wo[i, 2]), wi)
    g = wi[2] * cos_l / d2
    r, gg, b = f[0] * lr * g, f[1] * lg * g, f[2] * lb * g
    return r, gg, b, 0.212671 * r + 0.715160 * gg + 0.072169 * b


@njit(cache=False, parallel=True)
def _candidates(lights, env, strategy, kinds, params, point, gnormal, frame, wo, material, light, pmf, u, n_bounded,
                xyz, target, source):  # fmt: skip
    """Candidate (i, c): the point sampled on light[i, c] (picked with pmf[i, c]) from pixel i, its target p^ and its
    area-measure source density q = P(l) p_sa cos_l / d^2 (0: nothing)."""
    for i in prange(light.shape[0]):
        for c in range(light.shape[1]):
            target[i, c] = source[i, c] = 0.0
            row = light[i, c]
            if row >= n_bounded or pmf[i, c] <= 0.0:
                continue
            ls = light_sample_of(lights, env, row, strategy, False, point[i, 0], point[i, 1], point[i, 2],
                                 gnormal[i, 0], gnormal[i, 1], gnormal[i, 2], u[i, c, 0], u[i, c, 1])  # fmt: skip
            if ls.pdf <= 0.0 or not ls.distance < math.inf:
                continue
            t = ls.distance
            x, y, z = point[i, 0] + t * ls.wx, point[i, 1] + t * ls.wy, point[i, 2] + t * ls.wz
            n = light_normal(lights, row, x, y, z)
            cos_l = abs(n[0] * ls.wx + n[1] * ls.wy + n[2] * ls.wz)
            if cos_l <= 0.0:
                continue
            xyz[i, c, 0], xyz[i, c, 1], xyz[i, c, 2] = x, y, z
            target[i, c] = _target(lights, kinds, params, point, frame, wo, material, i, row, x, y, z)[3]
            source[i, c] = pmf[i, c] * ls.pdf * cos_l / (ls.distance * ls.distance)


@njit(cache=False, parallel=True)
def _targets(lights, kinds, params, point, frame, wo, material, at, light, xyz, out):
    """out[r] = p^ of pixel at[r] for the point xyz[r] on light[r]."""
    for r in prange(at.shape[0]):
        out[r] = 0.0
        if light[r] >= 0 and at[r] >= 0:
            out[r] = _target(lights, kinds, params, point, frame, wo, material, at[r], light[r], xyz[r, 0], xyz[r, 1],
                             xyz[r, 2])[3]  # fmt: skip


@njit(cache=False, parallel=True)
def _shade(lights, kinds, params, point, gnormal, error, frame, wo, material, light, xyz, weight, rgb, ray):
    """rgb[i] = f L G (unshadowed) x weight[i] of pixel i's kept sample, ray[i] its shadow ray."""
    for i in prange(light.shape[0]):
        rgb[i, 0] = rgb[i, 1] = rgb[i, 2] = 0.0
        if light[i] < 0 or weight[i] <= 0.0:
            continue
        x, y, z = xyz[i, 0], xyz[i, 1], xyz[i, 2]
        r, g, b, p = _target(lights, kinds, params, point, frame, wo, material, i, light[i], x, y, z)
        if p <= 0.0:
            continue
        rgb[i, 0], rgb[i, 1], rgb[i, 2] = r * weight[i], g * weight[i], b * weight[i]
        dx, dy, dz = x - point[i, 0], y - point[i, 1], z - point[i, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        wx, wy, wz = dx / d, dy / d, dz / d
        qx, qy, qz = ray_offset(point[i, 0], point[i, 1], point[i, 2], gnormal[i, 0], gnormal[i, 1], gnormal[i, 2],
                                error[i], wx, wy, wz)  # fmt: skip
        o = ray_to_light(lights, light[i], point[i, 0], point[i, 1], point[i, 2], qx, qy, qz, wx, wy, wz, d)
        for c in range(7):
            ray[i, c] = o[c]


def _resample(weights: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per row, the column kept in proportion to ``weights`` (rows summing to 0 keep column 0)."""
    cdf = np.cumsum(weights, axis=1)
    return np.minimum((cdf < (u * cdf[:, -1])[:, None]).sum(axis=1), weights.shape[1] - 1)


class Pass:
    """One pass's shading points (one jittered camera sample per pixel) and what the estimators share."""

    def __init__(self, scene, arrays, lights, env, tracer, sampler, seed: int, sample: int):
        from lightprobe.lab.camera_samples import camera_batch, shading_batch

        width, height = scene.camera.resolution
        self.width, self.height = width, height
        n = width * height
        pixels = np.arange(n, dtype=np.int64)
        rng = np.random.default_rng([seed, sample])
        self.rng = rng
        dirs = camera_batch(scene.camera.kernel_array(), pixels, rng.random((n, 2)))
        origin = np.asarray(scene.camera.origin, dtype=np.float64)
        t, kind, index, prim, b1, b2 = tracer.intersect(np.ascontiguousarray(np.broadcast_to(origin, dirs.shape)), dirs)
        self.point, self.gnormal, self.error, self.frame, self.wo, self.material = shading_batch(
            arrays, kind, index, prim, b1, b2, t, origin, dirs
        )
        self.valid = (self.material >= 0) & (self.wo[:, 2] > 0.0)
        self.material = np.where(self.valid, self.material, 0)
        self.arrays, self.lights, self.env, self.tracer, self.sampler = arrays, lights, env, tracer, sampler
        self.n_bounded = int(np.sum(~_infinite(lights)))
        self.seconds = {"candidates": 0.0, "targets": 0.0}
        self.counts = {"candidates": 0, "targets": 0}

    def candidates(self, m: int):
        """(light (N, m), pmf, points (N, m, 3), target, source) of m BVH candidates per pixel."""
        n = self.point.shape[0]
        u = self.rng.random((n, m, 3))
        light = np.empty((n, m), np.int64)
        pmf = np.empty((n, m))
        for c in range(m):
            light[:, c], pmf[:, c] = self.sampler.select(self.point, self.gnormal, u[:, c, 0])
        xyz, target, source = np.zeros((n, m, 3)), np.zeros((n, m)), np.zeros((n, m))
        start = time.perf_counter()
        _candidates(self.lights, self.env, STRATEGY, self.arrays.material_kind, self.arrays.material_params, self.point,
                    self.gnormal, self.frame, self.wo, self.material, light, pmf, np.ascontiguousarray(u[:, :, 1:]),
                    self.n_bounded, xyz, target, source)  # fmt: skip
        self.seconds["candidates"] += time.perf_counter() - start
        self.counts["candidates"] += n * m
        invalid = ~self.valid
        target[invalid], source[invalid] = 0.0, 0.0
        return light, pmf, xyz, target, source

    def targets(self, at: np.ndarray, light: np.ndarray, xyz: np.ndarray) -> np.ndarray:
        out = np.empty(at.shape[0])
        start = time.perf_counter()
        _targets(self.lights, self.arrays.material_kind, self.arrays.material_params, self.point, self.frame, self.wo,
                 self.material, np.ascontiguousarray(at), np.ascontiguousarray(light), np.ascontiguousarray(xyz),
                 out)  # fmt: skip
        self.seconds["targets"] += time.perf_counter() - start
        self.counts["targets"] += at.shape[0]
        return out

    def shade(self, light: np.ndarray, xyz: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """f L V G x weight of each pixel's kept sample (one shadow ray each)."""
        n = light.shape[0]
        rgb, ray = np.zeros((n, 3)), np.zeros((n, 7))
        light = np.where(self.valid, light, -1)
        _shade(self.lights, self.arrays.material_kind, self.arrays.material_params, self.point, self.gnormal,
               self.error, self.frame, self.wo, self.material, np.ascontiguousarray(light), np.ascontiguousarray(xyz),
               np.ascontiguousarray(weight), rgb, ray)  # fmt: skip
        live = np.flatnonzero(np.any(rgb > 0.0, axis=1))
        if live.size:
            blocked = self.tracer.occluded(ray[live, 0:3], ray[live, 3:6], ray[live, 6])
            rgb[live[blocked]] = 0.0
        return rgb

    def neighbours(self, k: int) -> np.ndarray:
        """(N, k) pixel indices within RADIUS of each pixel (-1: none there, or no shading point)."""
        n = self.point.shape[0]
        r = RADIUS * np.sqrt(self.rng.random((n, k)))
        phi = 2.0 * np.pi * self.rng.random((n, k))
        px, py = np.arange(n) % self.width, np.arange(n) // self.width
        qx = np.rint(px[:, None] + r * np.cos(phi)).astype(np.int64)
        qy = np.rint(py[:, None] + r * np.sin(phi)).astype(np.int64)
        inside = (qx >= 0) & (qx < self.width) & (qy >= 0) & (qy < self.height)
        q = np.where(inside, qy * self.width + qx, -1)
        q[(q == np.arange(n)[:, None])] = -1
        return np.where((q >= 0) & self.valid[np.maximum(q, 0)], q, -1)


def _infinite(lights) -> np.ndarray:
    from lightprobe.emitters.kinds import flag_rows

    return flag_rows(lights.kind, "infinite")


def bvh(p: Pass, k: int) -> np.ndarray:
    out = np.zeros((p.point.shape[0], 3))
    for _ in range(k):
        light, _, xyz, _, source = p.candidates(1)
        weight = np.where(source[:, 0] > 0, 1.0 / np.where(source[:, 0] > 0, source[:, 0], 1.0), 0.0)
        out += p.shade(light[:, 0], xyz[:, 0], weight)
    return out / k


def reservoirs(p: Pass, m: int):
    """Each pixel's RIS reservoir of m candidates: (light, point, W, target of the kept sample)."""
    light, _, xyz, target, source = p.candidates(m)
    w = np.where(source > 0.0, target / np.where(source > 0.0, source, 1.0), 0.0)
    kept = _resample(w, p.rng.random(w.shape[0]))
    rows = np.arange(w.shape[0])
    total = w.sum(axis=1)
    t = target[rows, kept]
    big_w = np.where((total > 0) & (t > 0), total / m / np.where(t > 0, t, 1.0), 0.0)
    return np.where(big_w > 0, light[rows, kept], -1), xyz[rows, kept], big_w, t


def ris(p: Pass, m: int) -> np.ndarray:
    light, xyz, big_w, _ = reservoirs(p, m)
    return p.shade(light, xyz, big_w)


def reuse(p: Pass, m: int, k: int) -> np.ndarray:
    """``ris m`` reservoirs, then k neighbours' resampled at each pixel with the generalised balance heuristic."""
    light, xyz, big_w, _ = reservoirs(p, m)
    n = light.shape[0]
    domains = np.concatenate([np.arange(n)[:, None], p.neighbours(k)], axis=1)  # (N, k + 1): the pixel first
    d = domains.shape[1]
    # candidate j of pixel i is domain j's reservoir sample; p^_t of it for every domain t of pixel i
    cand = np.where(domains >= 0, domains, 0)
    c_light = np.where(domains >= 0, light[cand], -1)  # (N, d)
    c_xyz = xyz[cand]  # (N, d, 3)
    c_w = np.where(domains >= 0, big_w[cand], 0.0)
    at = np.repeat(domains[:, None, :], d, axis=1)  # at[i, j, t] = domain t, for candidate j
    hat = p.targets(at.reshape(-1), np.repeat(c_light[:, :, None], d, axis=2).reshape(-1),
                    np.repeat(c_xyz[:, :, None, :], d, axis=2).reshape(-1, 3)).reshape(n, d, d)  # fmt: skip
    own = hat[:, :, 0]  # p^_i(y_j)
    total = hat.sum(axis=2)
    mine = hat[:, np.arange(d), np.arange(d)]  # p^_j(y_j)
    m_j = np.where(total > 0, mine / np.where(total > 0, total, 1.0), 0.0)
    w = m_j * own * c_w
    kept = _resample(w, p.rng.random(n))
    rows = np.arange(n)
    y_hat = own[rows, kept]
    weight = np.where(y_hat > 0, w.sum(axis=1) / np.where(y_hat > 0, y_hat, 1.0), 0.0)
    return p.shade(np.where(weight > 0, c_light[rows, kept], -1), c_xyz[rows, kept], weight)


ESTIMATORS = {
    "bvh": (lambda p: bvh(p, 1), 1, 0, 1),
    "bvh x2": (lambda p: bvh(p, 2), 2, 0, 2),
    "bvh x4": (lambda p: bvh(p, 4), 4, 0, 4),
    "ris 4": (lambda p: ris(p, 4), 4, 0, 1),
    "reuse 1, 4": (lambda p: reuse(p, 1, 4), 1, 25, 1),
    "reuse 4, 4": (lambda p: reuse(p, 4, 4), 4, 25, 1),
    "reuse 4, 8": (lambda p: reuse(p, 4, 8), 4, 81, 1),
}


def measure(name: str, spp: int, seed: int) -> list[dict]:
    from lightprobe import reference_scenes
    from lightprobe.emitters.envmap import placeholder_environment
    from lightprobe.emitters.selection import LightSampler
    from lightprobe.geometry.raytracer import RayTracer

    scene = reference_scenes.build(name, resolution=reference_scenes.SUITE_RESOLUTION)
    arrays, lights = scene.compile(), scene.light_table()
    env = (scene.environment if scene.environment is not None else placeholder_environment()).kernel
    environment = scene.environment
    sampler = LightSampler("bvh", lights, env_irradiance=environment.irradiance_terms if environment else None)
    tracer = RayTracer(arrays)
    sums = {e: [] for e in ESTIMATORS}
    timing = {"candidates": [0.0, 0], "targets": [0.0, 0]}
    try:
        for sample in range(spp):
            for e, (run, *_rest) in ESTIMATORS.items():
                p = Pass(scene, arrays, lights, env, tracer, sampler, seed, sample)  # the same points for each
                sums[e].append(run(p))
                if sample > 0:  # the first pass compiles
                    for key in timing:
                        timing[key][0] += p.seconds[key]
                        timing[key][1] += p.counts[key]
    finally:
        tracer.close()
    from lightprobe.analysis.metrics import block_z_test

    shape = (scene.camera.resolution[1], scene.camera.resolution[0], 3)
    images = {e: np.stack(v).reshape(spp, *shape) for e, v in sums.items()}
    mean = np.mean([im.mean(axis=0) for im in images.values()], axis=0)
    ns = {key: 1e9 * s / max(c, 1) for key, (s, c) in timing.items()}
    camera_ns, candidate_ns = COSTS_NS.get(name, (550, 150))
    truth = images["bvh x4"]
    rows = []
    base = None
    for e, (_, candidates, evaluations, rays) in ESTIMATORS.items():
        im = images[e]
        var = im.var(axis=0, ddof=1)  # one pass's variance per pixel
        relmse = float(np.mean(var / (mean * mean + 0.01)))
        # a camera sample's predicted time: the default's, plus the extra candidates (each a pick, a light sample and
        # a BSDF evaluation; bvh xK's are K light samples with their shadow rays) and the target evaluations
        predicted = camera_ns + (candidates - 1) * candidate_ns + evaluations * ns["targets"] + (rays - 1) * SHADOW_NS
        z = block_z_test(im.mean(axis=0), var / spp, truth.mean(axis=0), truth.var(axis=0, ddof=1) / spp, block=8)
        row = {"scene": name, "estimator": e, "relmse_per_pass": relmse, "candidates": candidates,
               "target_evaluations": evaluations, "shadow_rays": rays, "predicted_ns": predicted,
               "pooled_z_vs_bvh_x4": z["pooled_z"], "outliers": z["outliers"]}  # fmt: skip
        if base is None:
            base = row
        row["variance_vs_bvh"] = relmse / base["relmse_per_pass"]
        row["predicted_efficiency_vs_bvh"] = (base["relmse_per_pass"] * base["predicted_ns"]) / (relmse * predicted)
        row["efficiency_per_shadow_ray_vs_bvh"] = base["relmse_per_pass"] / (relmse * rays)
        rows.append(row)
    for row in rows:
        row["measured_ns_per_candidate"] = ns["candidates"]
        row["measured_ns_per_target"] = ns["targets"]
    return rows


def main() -> int:
    import json

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=["dome", "building", "ceiling", "many"])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()
    every = []
    for name in args.scenes:
        rows = measure(name, args.spp, args.seed)
        every += rows
        for row in rows:
            print(json.dumps(row), flush=True)
    print("\n| scene | estimator | candidates, target evaluations, shadow rays | variance over bvh's | pooled z vs "
          "bvh x4 | predicted ns | predicted efficiency over bvh | per shadow ray |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for r in every:
        print(f"| {r['scene']} | {r['estimator']} | {r['candidates']}, {r['target_evaluations']}, {r['shadow_rays']} | "
              f"{r['variance_vs_bvh']:.3f} | {r['pooled_z_vs_bvh_x4']:+.2f} | {r['predicted_ns']:.0f} | "
              f"{r['predicted_efficiency_vs_bvh']:.2f}x | {r['efficiency_per_shadow_ray_vs_bvh']:.2f}x |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
