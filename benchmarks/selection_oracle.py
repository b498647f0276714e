#!/usr/bin/env python3
"""How far each light selector is from the best possible one, on a suite scene (issue 59, item 3's oracle).

    python benchmarks/selection_oracle.py                    # the building, 300 points, 16 samples per light
    python benchmarks/selection_oracle.py --scene city --points 200

At ``--points`` shading points the camera sees (pixel centres, Lambertian surfaces), every bounded light's true
contribution C_l = (albedo / pi) integral of L cos V over the light is estimated by brute force: ``--light-samples``
stratified samples on each light, each with its shadow ray.  A selector that picks light l with probability p_l
(then samples the light exactly) has a one-sample estimate of sum C with relative second moment
sum_l (C_l^2 / p_l) / (sum C)^2; 1 is the best possible (the oracle, p_l proportional to C_l, visibility included),
and it minus 1 is the relative variance that the choice of light adds.  Printed per selector, the mean and the median
over the points, for the BVH (what lightprobe picks by default), the learned selector (what a 64-spp render of the
scene learned: ``light_sampler = "learned"``), and two oracles: the unoccluded one (p_l proportional to the light's
contribution without shadows: the best any selector blind to visibility can do) and the true one (1 by construction).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))


def _learned_selector(scene, spp: int):
    """The selector a render of ``scene`` at ``spp`` learned (and that render's shading points at 1 spp)."""
    from lightprobe.integrators import light_learning
    from lightprobe.integrators.wavefront import RenderSettings, render

    kept = {}
    original = light_learning.Learning.learn

    def learn(self):
        kept["selector"] = original(self)
        return kept["selector"]

    light_learning.Learning.learn = learn
    try:
        render(scene, RenderSettings(spp=spp, light_sampler="learned", seed=7))
    finally:
        light_learning.Learning.learn = original
    return kept["selector"]


def _shading_points(scene, count: int, seed: int):
    """(points, normals, albedo luminance) of up to ``count`` pixel centres whose camera ray meets a Lambertian
    surface, each point offset along its normal toward the camera."""
    from lightprobe.bsdfs.lambert import LAMBERT
    from lightprobe.integrators import wavefront
    from lightprobe.integrators.wavefront import RenderSettings

    kept = {}
    original = wavefront._Pass.run

    def run(self, acc, pixels, spp_now, sample_start):
        rays = original(self, acc, pixels, spp_now, sample_start)
        n = pixels.size * spp_now
        kept.update(point=self.cams.point[:n].copy(), normal=self.cams.gnormal[:n].copy(),
                    material=self.cams.material[:n].copy(), pixels=pixels.copy(), arrays=self.scene)  # fmt: skip
        return rays

    wavefront._Pass.run = run
    try:
        wavefront.render(scene, RenderSettings(spp=1, adaptive=False, seed=seed))
    finally:
        wavefront._Pass.run = original
    arrays = kept["arrays"]
    material = kept["material"]
    lambert = (material >= 0) & (arrays.material_kind[np.maximum(material, 0)] == LAMBERT)
    rows = np.flatnonzero(lambert)
    rows = np.random.default_rng(seed).choice(rows, min(count, rows.size), replace=False)
    albedo = np.array([_albedo(scene, m) for m in material[rows]])
    return kept["point"][rows], kept["normal"][rows], albedo


def _albedo(scene, material_index: int) -> float:
    """The luminance of a Lambertian material's albedo, by its index in the scene's materials."""
    from lightprobe.color import luminance

    material = list(scene.materials.values())[material_index]
    return float(luminance(np.asarray(material.albedo, dtype=np.float64)))


def contributions(scene, lights, points, normals, albedo, per_light: int, tracer) -> tuple[np.ndarray, np.ndarray]:
    """(with shadows, without) each bounded light's contribution at each point: (points, lights) arrays of the
    luminance of (albedo / pi) L cos / pdf averaged over ``per_light`` stratified samples of the light."""
    from lightprobe.emitters.kinds import flag_rows
    from lightprobe.emitters.lights import sample_batch

    bounded = np.flatnonzero(~flag_rows(lights.kind, "infinite"))
    n, k = points.shape[0], per_light
    side = int(np.sqrt(k))
    grid = (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2) + 0.5) / side
    rng = np.random.default_rng(3)
    seen = np.zeros((n, bounded.size))
    open_ = np.zeros((n, bounded.size))
    p = np.repeat(points, grid.shape[0], axis=0)
    nrm = np.repeat(normals, grid.shape[0], axis=0)
    for j, light in enumerate(bounded):
        u = (np.tile(grid, (n, 1)) + rng.random((n * grid.shape[0], 2)) / side) % 1.0
        s = sample_batch(lights, int(light), p, nrm, u)
        w, dist, radiance, pdf = s[:, 0:3], s[:, 3], s[:, 4:7], s[:, 7]
        cos = np.maximum(np.einsum("ij,ij->i", w, nrm), 0.0)
        lum = radiance @ np.array([0.212671, 0.715160, 0.072169])
        value = np.where(pdf > 0.0, lum * cos / np.where(pdf > 0.0, pdf, 1.0), 0.0)
        live = value > 0.0
        blocked = np.zeros(value.size, bool)
        if live.any():
            origins = p[live] + 1e-4 * nrm[live]  # off the surface, on the lit side (cos > 0)
            blocked[live] = tracer.occluded(origins, w[live], dist[live] * (1.0 - 1e-4))
        open_[:, j] = value.reshape(n, -1).mean(axis=1)
        seen[:, j] = np.where(blocked, 0.0, value).reshape(n, -1).mean(axis=1)
    scale = (albedo / np.pi)[:, None]
    return seen * scale, open_ * scale


def relative_second_moment(c: np.ndarray, pmf: np.ndarray) -> np.ndarray:
    """Per point, sum_l C_l^2 / p_l / (sum C)^2 (inf where a light that gives something has p_l = 0)."""
    total = c.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(c > 0.0, c * c / pmf, 0.0)
    return terms.sum(axis=1) / np.maximum(total * total, 1e-300)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="building")
    parser.add_argument("--points", type=int, default=300)
    parser.add_argument("--light-samples", type=int, default=16, help="per light and point (a square number)")
    parser.add_argument("--learn-spp", type=int, default=64, help="the render whose learning is measured")
    args = parser.parse_args()
    from lightprobe.emitters.selection import LightSampler
    from lightprobe.geometry.raytracer import RayTracer
    from lightprobe.reference_scenes import build

    start = time.perf_counter()
    scene = build(args.scene)
    lights = scene.light_table()
    learned = _learned_selector(build(args.scene), args.learn_spp)
    points, normals, albedo = _shading_points(build(args.scene), args.points, seed=11)
    tracer = RayTracer(scene.compile())
    try:
        seen, unoccluded = contributions(scene, lights, points, normals, albedo, args.light_samples, tracer)
    finally:
        tracer.close()
    bvh = LightSampler("bvh", lights)
    mine = LightSampler("bvh", lights)
    mine.arrays = learned
    n_bounded = seen.shape[1]
    rows = {"bvh": [], "learned": []}
    for i in range(points.shape[0]):
        for name, sampler in (("bvh", bvh), ("learned", mine)):
            pmf = sampler.pmf(points[i], normals[i])[:n_bounded]
            rows[name].append(pmf / max(pmf.sum(), 1e-300))  # given a bounded pick (no infinite light here)
    lit = seen.sum(axis=1) > 0.0
    print(f"{args.scene}: {points.shape[0]} Lambertian points, {lit.sum()} lit; {n_bounded} lights; "
          f"{args.light_samples} samples a light; the share of their unoccluded light that arrives: "
          f"{seen[lit].sum() / unoccluded[lit].sum():.3f}")  # fmt: skip
    selectors = {
        "bvh": np.array(rows["bvh"]),
        "learned": np.array(rows["learned"]),
        "unoccluded oracle": unoccluded / np.maximum(unoccluded.sum(axis=1, keepdims=True), 1e-300),
        "oracle": seen / np.maximum(seen.sum(axis=1, keepdims=True), 1e-300),
    }
    for name, pmf in selectors.items():
        m = relative_second_moment(seen[lit], pmf[lit]) - 1.0
        print(f"  {name:18s} relative variance added by the choice of light: mean {np.mean(m):9.3f}  "
              f"median {np.median(m):8.3f}  90th percentile {np.quantile(m, 0.9):9.3f}")  # fmt: skip
    print(f"  ({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
