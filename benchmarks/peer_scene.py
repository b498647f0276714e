#!/usr/bin/env python3
"""Benchmark: the peer scene of ../shared/peers (512x512, the renderer's defaults: MIS with 8 BSDF + 8
environment samples per camera sample, decisions 33, 34 and 93).

    python benchmarks/peer_scene.py                 # 16, 64 and 256 spp, one JSON line each (fresh process each)
    python benchmarks/peer_scene.py --spp 64        # one configuration, one JSON line
    python benchmarks/peer_scene.py --spp 64 --reference ref.exr --out mine.exr

Each line has: seconds (render loop, after scene setup and kernel warm-up), samples_per_s (camera samples,
res^2 * spp / seconds, Mitsuba's definition), rays_per_s (camera + shadow rays), embree_rays (the rays of those that
reached a mesh's bounds; the kernels trace them through Embree themselves, so their time is part of the kernels' in
the profile), peak_mb (max resident memory of the process), cores,
and relmse = mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01) when --reference is given (the peer
kit's metric), with ref_floor, the part of it that is the reference's own noise, when the reference's variance
(``ref4096_var.exr`` beside ``ref4096.exr``, from the kit's ``--variance-out``) is found: relmse - ref_floor is the
error the image really has.  For comparison: Mitsuba 3's llvm variant renders this scene at about 10 M samples/s
on this machine's 2 cores (../shared/peers/README.md).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys

import numpy as np


def _replace_blob(path: str) -> None:
    """Put the mesh at ``path`` in the blob's place: scaled uniformly and centred into the blob's bounding box
    (its largest extent matched), so the image stays comparable."""
    import lightprobe.peer as peer
    from lightprobe.geometry.mesh import TriangleMesh

    original = peer.peer_assets

    def assets(peers=None):
        env, blob_v, _ = original(peers)
        mesh = TriangleMesh.load(path)
        v = mesh.vertices
        lo, hi = v.min(axis=0), v.max(axis=0)
        blo, bhi = blob_v.min(axis=0), blob_v.max(axis=0)
        scale = (bhi - blo).max() / (hi - lo).max()
        v = (v - (lo + hi) / 2) * scale + (blo + bhi) / 2
        return env, v, mesh.faces

    peer.peer_assets = assets


def run_one(args) -> dict:
    from lightprobe.analysis.metrics import relmse
    from lightprobe.geometry.raytracer import RayTracer
    from lightprobe.images import read_image, write_image
    from lightprobe.integrators import wavefront
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.peer import peer_scene, reference_floor

    if args.mesh:
        _replace_blob(args.mesh)
    env_options = {"pdf": args.pdf, "pdf_weights": args.pdf_weights, "pdf_resolution": args.pdf_resolution}
    scene = peer_scene(resolution=(args.res, args.res), **{k: v for k, v in env_options.items() if v is not None})
    settings = RenderSettings(
        spp=args.spp,
        strategy=args.strategy,
        heuristic=args.heuristic,  # None: the renderer's default
        seed=args.seed,
        threads=args.threads,
        sampler=args.sampler,
        mis_compensation={"auto": None, "on": True, "off": False}[args.mis_compensation],
        n_bsdf=args.bsdf_samples,
        n_env=args.env_samples,
        env_candidates=args.env_candidates,
        adaptive=args.adaptive,
        time_limit=args.time_limit,
        **({"pass_samples": args.pass_samples} if args.pass_samples else {}),
    )
    tracer = RayTracer(scene.compile(), threads=args.threads or os.cpu_count() or 1)
    if args.profile:
        wavefront.PROFILE = {}
    result = render(scene, settings, tracer=tracer)
    profile, wavefront.PROFILE = wavefront.PROFILE, None
    stats = result.stats
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    line = {
        "renderer": "lightprobe",
        "scene": "peer",
        "res": args.res,
        "spp": args.spp,
        "mesh": args.mesh or "blob (98k triangles)",
        "triangles": stats["triangles"],
        "strategy": args.strategy,
        "heuristic": stats["heuristic"],
        "sampler": args.sampler,
        "mis_compensation": stats["mis_compensation"],
        "bsdf_samples": stats["n_bsdf"],
        "env_samples": stats["n_env"],
        "env_candidates": args.env_candidates,
        "adaptive": stats["adaptive"],
        "time_limit": args.time_limit,
        "spp_mean": round(float(result.counts.mean()), 3),
        **{k: stats[k] for k in _PLAN_KEYS if k in stats},
        "env_pdf": [scene.environment.pdf_mode, scene.environment.pdf_weights, scene.environment.pdf_resolution],
        "seconds": round(stats["seconds"], 4),
        "samples_per_s": round(stats["samples_per_s"]),
        "rays_per_s": round(stats["rays_per_s"]),
        "camera_rays": stats["camera_rays"],
        "shadow_rays": stats["shadow_rays"],
        "embree_rays": stats["embree_rays"],
        "setup_seconds": round(stats["setup_seconds"], 3),
        "peak_mb": round(peak_mb, 1),
        "cores": os.cpu_count(),
        "threads": stats["threads"],
    }
    if profile is not None:
        stages = {name: round(t, 3) for name, t in sorted(profile.items(), key=lambda kv: -kv[1])}
        stages["other (Python between kernels)"] = round(stats["seconds"] - sum(profile.values()), 3)
        line["profile_seconds"] = stages
    if args.reference:
        ref = read_image(args.reference)[:, :, :3]
        line["relmse"] = relmse(result.image, ref)
        line["reference"] = args.reference
        if (floor := reference_floor(args.reference)) is not None:
            line["ref_floor"] = floor
        if args.by_object:
            line["by_object"] = _by_object(scene, result.image, ref, args.reference)
    if args.out:
        write_image(args.out, result.image)
        line["out"] = args.out
    return line


def _by_object(scene, image: np.ndarray, ref: np.ndarray, reference: str) -> dict:
    """Where the relMSE is: per object seen at the pixels' centres (``sky`` where none is), its share of the
    pixels and its part of the image's relMSE (the mean over its pixels x that share, so the parts add up to the
    image's), with the reference's own noise there (``floor``) when its variance is beside it."""
    from lightprobe.analysis.masks import object_id_pass
    from lightprobe.analysis.metrics import relmse
    from lightprobe.peer import reference_noise

    ids, names = object_id_pass(scene)
    noise = reference_noise(reference)
    parts = {}
    for index, name in [(-1, "sky"), *enumerate(names)]:
        mask = ids == index
        if not mask.any():
            continue
        share = float(mask.mean())
        parts[name] = {"pixels": round(share, 4), "relmse": relmse(image, ref, mask) * share}
        if noise is not None:
            parts[name]["floor"] = float(noise[mask].sum(dtype=np.float64) / noise.size)
    return parts


# an adaptive render's plan under a time limit (integrators/adaptive.py), and whether the limit stopped it
_PLAN_KEYS = (
    "adaptive_pilot_spp",
    "adaptive_pilot_seconds",
    "adaptive_seconds_per_spp",
    "adaptive_mean_planned",
    "stopped_by_time_limit",
)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spp", type=int, help="samples per pixel (default: 16, 64, 256 in separate processes)")
    parser.add_argument("--res", type=int, default=512)
    parser.add_argument("--strategy", default="mis")
    parser.add_argument("--heuristic", help="balance or power [the renderer's default]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sampler", default="sobol", help="sobol or independent")
    parser.add_argument("--mis-compensation", choices=["auto", "on", "off"], default="auto")
    parser.add_argument("--bsdf-samples", type=int, help="BSDF samples per camera sample [the renderer's default]")
    parser.add_argument(
        "--env-samples", type=int, help="environment samples per camera sample [the renderer's default]"
    )
    parser.add_argument("--env-candidates", type=int, default=1, help="RIS candidates per environment sample")
    parser.add_argument("--threads", type=int)
    parser.add_argument(
        "--adaptive",
        action=argparse.BooleanOptionalAction,
        help="per-pixel adaptive sampling (spp on average), or uniform counts [the renderer's default: adaptive]",
    )
    parser.add_argument("--time-limit", type=float, help="stop (or, adaptive, plan the counts) at these seconds")
    parser.add_argument("--pass-samples", type=int, help="camera samples per wavefront pass [the renderer's default]")
    parser.add_argument("--reference", help="EXR to compute relMSE against")
    parser.add_argument("--out", help="write the render here")
    parser.add_argument("--profile", action="store_true", help="add seconds per kernel (warm-up excluded)")
    parser.add_argument(
        "--by-object", action="store_true", help="with --reference: each object's part of the relMSE (and floor)"
    )
    parser.add_argument("--pdf", choices=["exact", "pbrt", "bilinear"], help="the environment PDF [bilinear]")
    parser.add_argument("--pdf-weights", choices=["bilinear", "texel", "blur"], help="exact/pbrt PDFs [bilinear]")
    parser.add_argument(
        "--pdf-resolution", type=int, help="exact/pbrt PDFs: PDF grid / map resolution [2 up to 2K maps]"
    )
    parser.add_argument("--mesh", help="a mesh file to put in the blob's place (e.g. the 871k-triangle dragon)")
    args = parser.parse_args(argv)
    if args.by_object and not args.reference:
        parser.error("--by-object needs --reference (the image to measure the error against)")

    from lightprobe.peer import find_peers

    if find_peers() is None:
        print(json.dumps({"skipped": "../shared/peers not found (set LIGHTPROBE_PEERS)"}))
        return 0
    if args.spp is not None:
        print(json.dumps(run_one(args)), flush=True)
        return 0
    for spp in (16, 64, 256):
        cmd = [
            sys.executable,
            __file__,
            "--spp",
            str(spp),
            "--res",
            str(args.res),
            "--strategy",
            args.strategy,
            "--seed",
            str(args.seed),
            "--sampler",
            args.sampler,
            "--mis-compensation",
            args.mis_compensation,
        ]
        if args.heuristic:
            cmd += ["--heuristic", args.heuristic]
        if args.bsdf_samples is not None:
            cmd += ["--bsdf-samples", str(args.bsdf_samples)]
        if args.env_samples is not None:
            cmd += ["--env-samples", str(args.env_samples)]
        if args.threads:
            cmd += ["--threads", str(args.threads)]
        if args.adaptive is not None:
            cmd += ["--adaptive" if args.adaptive else "--no-adaptive"]
        if args.time_limit is not None:
            cmd += ["--time-limit", str(args.time_limit)]
        if args.reference:
            cmd += ["--reference", args.reference] + (["--by-object"] if args.by_object else [])
        subprocess.run(cmd, check=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
