#!/usr/bin/env python3
"""Benchmark: area lights and many lights, lightprobe's light selectors against Mitsuba 3's best configuration.

    pip install -e '.[peers]'                          # Mitsuba 3.9.1 (Debian: apt-get install libllvm19)
    python benchmarks/lights_vs_mitsuba.py             # scenes area and many, 320x240, 64 spp, 8 seeds, 2 reps
    python benchmarks/lights_vs_mitsuba.py --scenes area --selectors bvh --reps 1
    python benchmarks/lights_vs_mitsuba.py --selectors bvh --uniform   # each selector with uniform counts too
    python benchmarks/lights_vs_mitsuba.py --selectors bvh --without-outlines   # and without the outline variate
    python benchmarks/lights_vs_mitsuba.py --selectors bvh --lights-per-sample 1 2   # rows with K = 1 and K = 2

The scenes are :mod:`lightprobe.reference_scenes` ``area`` (a rectangle, a sphere and a 16-triangle ring light over a
16 m ground under a dim sky) and ``many`` (``--many-lights`` small rectangle lights, 2,000 by default, over three
decades of power, no sky), at ``--resolution``. The reference of each is Mitsuba's own (``direct``, ``multijitter``,
1 + 1, passes of 64 spp: 1,024 for ``area`` (about 4 minutes on 2 cores), 512 for ``many``, whose error is larger;
``--ref-passes`` sets both), made once and cached in ``--cache``; its relMSE floor, mean(var / (ref^2 + 0.01)), is
printed and subtracted for ``true_efficiency`` (at most a ninth of every error measured; a thirty-fourth on ``area``).
Each configuration renders ``--seeds`` images at ``--spp`` (8 by default: an image's relMSE is heavy-tailed, a few
pixels on a bright emitter's outline that one camera sample in hundreds hits, so one seed in four can read 3-4x the
median; decisions.md 94); relMSE is their mean, seconds their median (the renderer's own timing, kernels compiled
first). Mitsuba runs every sampler at 1 + 1 and 4 + 4 emitter + BSDF samples (its ``direct`` integrator), on ``many``
also with each emitter's ``sampling_weight`` set to its power ("power"); lightprobe every selector with its defaults
(adaptive counts since decisions.md 99; with ``--uniform``, also with uniform counts: "bvh uniform"; with
``--without-outlines``, also without the outline control variate of decisions.md 96: "bvh, no outline variate"; with
``--lights-per-sample``, with each K given instead of the default, 2 here: "bvh K=1").  Each row also gives
``relmse_emitter_edges``, the share of relMSE from the pixels next to a directly seen emitter (its outline: a pixel
there is mostly the count of its camera samples that hit the emitter, so this part measures the camera samples'
stratification, not the lights' sampling; decisions.md 91). Renderers run in alternating subprocesses (A B A B) so that
drifting machine load hits both alike.  One JSON line per configuration, then the best of each renderer per scene and
their ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MITSUBA_SAMPLERS = ("independent", "stratified", "multijitter", "ldsampler")


def _emitter_edges(args) -> np.ndarray:
    """(H, W) bool: the pixels whose centre sees an emitter directly (lightprobe's object-id pass), grown by one
    pixel, so every pixel an emitter's outline crosses is in: where a pixel's estimate is mostly how many of its
    camera samples hit the emitter, whatever the lights' sampling."""
    from lightprobe.analysis.masks import object_id_pass
    from lightprobe.reference_scenes import build

    scene = build(args.scene, resolution=tuple(args.resolution), lights=_lights(args, args.scene))
    ids, _ = object_id_pass(scene)
    emitters = [i for i, o in enumerate(scene.objects) if o.emission is not None]
    seen = np.isin(ids, emitters)
    near = seen.copy()
    near[1:] |= seen[:-1]
    near[:-1] |= seen[1:]
    grown = near.copy()
    grown[:, 1:] |= near[:, :-1]
    grown[:, :-1] |= near[:, 1:]
    return grown


def _relmse(image, ref, edges) -> tuple[float, float]:
    """(relMSE, the emitter edges' share of it: their pixels' relMSE times their fraction of the image, so total =
    edges + the rest; as ``peer_scene.py`` splits its error by object)."""
    from lightprobe.analysis.metrics import relmse

    share = relmse(image, ref, edges) * float(edges.mean()) if edges.any() else 0.0
    return relmse(image, ref), share


def _row(who, scene, config, errors, seconds, floor, edge_errors) -> dict:
    e, t = float(np.mean(errors)), float(np.median(seconds))
    return {
        "renderer": who,
        "scene": scene,
        "config": config,
        "relmse": e,
        "relmse_emitter_edges": float(np.mean(edge_errors)),
        "seconds": round(t, 3),
        "efficiency": 1.0 / (e * t),
        "true_efficiency": 1.0 / (max(e - floor, 1e-30) * t),
        "floor": floor,
    }


def _mitsuba_worker(args) -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import mitsuba_references as mr

    mr._prefer_llvm19()
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    import lightprobe.reference_scenes as rs
    from lightprobe.images import write_image

    rs.RESOLUTION = tuple(args.resolution)
    desc = rs.describe(args.scene, lights=_lights(args, args.scene))
    ref_file = _reference_file(args, args.scene)
    with tempfile.TemporaryDirectory() as tmp:
        env_file = None
        image = rs.environment_image(desc)
        if image is not None:
            env_file = str(Path(tmp) / "env.exr")
            write_image(env_file, image)
        if args.reference:
            passes = _passes(args, args.scene)
            print(json.dumps(mr.render(args.scene, 64, passes, ref_file, lights=_lights(args, args.scene))), flush=True)
            return
        ref = np.load(ref_file)
        floor = float(np.mean(ref["variance"] / (ref["mean"].astype(np.float64) ** 2 + 0.01)))
        edge_mask = _emitter_edges(args)
        for sampler in MITSUBA_SAMPLERS:
            for n in (1, 4):
                for weights in (False, True) if args.scene == "many" else (False,):
                    d = mr.scene_dict(mi, desc, env_file, args.spp, tmp, power_weights=weights)
                    d["integrator"] = {"type": "direct", "emitter_samples": n, "bsdf_samples": n}
                    d["sensor"]["sampler"] = {"type": sampler, "sample_count": args.spp}
                    scene = mi.load_dict(d)
                    mi.render(scene, spp=args.spp, seed=10_000)  # compile
                    errors, seconds, edges = [], [], []
                    for s in range(args.seeds):
                        start = time.perf_counter()
                        x = np.array(mi.render(scene, spp=args.spp, seed=s + 1), dtype=np.float64)
                        seconds.append(time.perf_counter() - start)
                        error, edge_error = _relmse(x, ref["mean"], edge_mask)
                        errors.append(error)
                        edges.append(edge_error)
                    config = f"{sampler} {n}+{n}" + (" power" if weights else "")
                    print(json.dumps(_row("mitsuba", args.scene, config, errors, seconds, floor, edges)), flush=True)


def _lightprobe_worker(args) -> None:
    sys.path.insert(0, str(ROOT / "src"))
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.reference_scenes import build

    ref = np.load(_reference_file(args, args.scene))
    floor = float(np.mean(ref["variance"] / (ref["mean"].astype(np.float64) ** 2 + 0.01)))
    edge_mask = _emitter_edges(args)
    lights = _lights(args, args.scene)
    render(build(args.scene, resolution=(32, 24), lights=lights), RenderSettings(spp=4))  # compile
    outline_choices = (True, False) if args.without_outlines else (True,)
    picks = args.lights_per_sample or [None]
    counts = (None, False) if args.uniform else (None,)  # the defaults' rows first, then uniform counts
    configs = [
        (selector, adaptive, o, k)
        for adaptive in counts
        for selector in args.selectors
        for o in outline_choices
        for k in picks
    ]
    for selector, adaptive, outline, k in configs:
        errors, seconds, edges = [], [], []
        for s in range(args.seeds):
            scene = build(args.scene, resolution=tuple(args.resolution), lights=lights)
            settings = RenderSettings(
                spp=args.spp,
                seed=s + 20,
                light_sampler=selector,
                adaptive=adaptive,
                outline_control_variate=outline,
                lights_per_sample=k,
            )
            r = render(scene, settings)
            image = r.image[..., :3].astype(np.float64)
            error, edge_error = _relmse(image, ref["mean"], edge_mask)
            errors.append(error)
            edges.append(edge_error)
            seconds.append(r.stats["seconds"])
        config = selector + ("" if k is None else f" K={k}") + (" uniform" if adaptive is False else "")
        config += "" if outline else ", no outline variate"
        print(json.dumps(_row("lightprobe", args.scene, config, errors, seconds, floor, edges)), flush=True)


# 65,536 and 32,768 spp: relMSE floors 2.2e-7 and 1.6e-4, a thirty-fourth and a ninth of lightprobe's error with its
# default adaptive counts.  The area scene's 16,384-spp reference (floor 8.9e-7) was a tenth of it, and its noise sat
# on the emitters' outline pixels, where lightprobe's image is exact (the outline control variate): there it was most
# of lightprobe's measured error (decisions.md 99; 4,096 and 8,192 spp before decision 96).
REFERENCE_PASSES = {"area": 1024, "many": 512}


def _passes(args, scene: str) -> int:
    return args.ref_passes or REFERENCE_PASSES[scene]


def _lights(args, scene: str) -> int | None:
    return args.many_lights if scene == "many" else None


def _reference_file(args, scene: str) -> Path:
    w, h = args.resolution
    name = f"many{args.many_lights}" if scene == "many" else scene
    return Path(args.cache) / f"{name}_{w}x{h}_{64 * _passes(args, scene)}spp_mitsuba.npz"


def _run(args, worker: str, scene: str, *extra: str) -> list[dict]:
    cmd = [
        sys.executable,
        __file__,
        "--worker",
        worker,
        "--scene",
        scene,
        "--spp",
        str(args.spp),
        "--seeds",
        str(args.seeds),
        "--resolution",
        *map(str, args.resolution),
        "--cache",
        args.cache,
        *(["--ref-passes", str(args.ref_passes)] if args.ref_passes else []),
        "--selectors",
        *args.selectors,
        "--many-lights",
        str(args.many_lights),
        *(["--uniform"] if args.uniform else []),
        *(["--without-outlines"] if args.without_outlines else []),
        *(["--lights-per-sample", *map(str, args.lights_per_sample)] if args.lights_per_sample else []),
        *extra,
    ]
    out = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    if out.returncode != 0:
        sys.path.insert(0, str(ROOT / "benchmarks"))  # as _mitsuba_worker does
        from mitsuba_references import llvm_crash

        remedy = llvm_crash(out.stderr)  # one line where Dr.Jit aborted in an old libLLVM, not LLVM's dump
        raise SystemExit(f"{worker} failed: {remedy}" if remedy else f"{worker} failed:\n{out.stderr[-2000:]}")
    rows = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    for row in rows:
        print(json.dumps(row), flush=True)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=["area", "many"], choices=["area", "many"])
    parser.add_argument("--selectors", nargs="*", default=["power", "bvh"])
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument(
        "--uniform", action="store_true", help="also each lightprobe selector with uniform counts (no adaptive)"
    )
    parser.add_argument(
        "--without-outlines", action="store_true", help="also each lightprobe row without the outline control variate"
    )
    parser.add_argument(
        "--lights-per-sample",
        type=int,
        nargs="*",
        help="lightprobe's rows with each of these K (lights picked per camera sample) [the renderer's default]",
    )
    parser.add_argument("--seeds", type=int, default=8, help="images per configuration (relMSE: their mean) [8]")
    parser.add_argument("--reps", type=int, default=2, help="repetitions of the A B sequence")
    parser.add_argument("--resolution", type=int, nargs=2, default=[320, 240])
    parser.add_argument("--many-lights", type=int, default=2000, help="the many-light scene's lights [2000]")
    parser.add_argument("--ref-passes", type=int, help="the references' passes of 64 spp [area 256, many 512]")
    parser.add_argument("--cache", default=str(Path.home() / ".cache" / "lightprobe" / "lights_vs_mitsuba"))
    parser.add_argument("--worker", choices=["mitsuba", "lightprobe"], help=argparse.SUPPRESS)
    parser.add_argument("--scene", help=argparse.SUPPRESS)
    parser.add_argument("--reference", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker == "mitsuba":
        _mitsuba_worker(args)
        return 0
    if args.worker == "lightprobe":
        _lightprobe_worker(args)
        return 0
    Path(args.cache).mkdir(parents=True, exist_ok=True)
    print(json.dumps({"cores": os.cpu_count(), "spp": args.spp, "resolution": args.resolution}), flush=True)
    for scene in args.scenes:
        if not _reference_file(args, scene).exists():
            _run(args, "mitsuba", scene, "--reference")
        rows = []
        for _ in range(args.reps):
            rows += _run(args, "mitsuba", scene) + _run(args, "lightprobe", scene)
        best = {}
        for who in ("mitsuba", "lightprobe"):
            mine = [r for r in rows if r["renderer"] == who]
            best[who] = max(mine, key=lambda r: r["efficiency"])
        ratio = best["lightprobe"]["efficiency"] / best["mitsuba"]["efficiency"]
        print(
            f"{scene}: lightprobe best {best['lightprobe']['config']} efficiency {best['lightprobe']['efficiency']:.0f}"
            f" (relMSE {best['lightprobe']['relmse']:.3g}, {best['lightprobe']['seconds']} s); Mitsuba best "
            f"{best['mitsuba']['config']} {best['mitsuba']['efficiency']:.0f} (relMSE {best['mitsuba']['relmse']:.3g},"
            f" {best['mitsuba']['seconds']} s): {ratio:.2f}x; relMSE at the emitters' edges "
            f"{best['lightprobe']['relmse_emitter_edges']:.3g} and {best['mitsuba']['relmse_emitter_edges']:.3g}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
