#!/usr/bin/env python3
"""Is lightprobe's image of a suite scene the reference's, block by block?  Errors from the spread between seeds.

::

    python benchmarks/block_z.py --scene peer --spp 512 --seeds 8 --option adaptive=false
    python benchmarks/block_z.py --scene peer --spp 512 --seeds 8 --region blob:40:120:112:200

lightprobe renders the scene ``--seeds`` times (seeds 100, 101, ...) at ``--spp``, and the mean image is compared
with the scene's Mitsuba reference kept by ``benchmarks/suite.py`` in ``--cache`` (make or extend one with
``python benchmarks/suite.py --worker reference --scene SCENE --spp 256 --reference-minutes M``): over blocks of
``--block`` x ``--block`` pixels, each channel's z = (lightprobe - reference) / sqrt(var_lp + var_ref), var_lp
the variance of the block's mean over the seeds / seeds, var_ref the reference's from its passes (plus the suite's
float32 round-off allowance, per pixel).  The accumulator's own per-sample variance is not used: it overstates a
Sobol' render's error (about 28-fold in variance at 2,048 spp on the peer scene, docs/performance.md), which would
hide a bias; the seeds' spread does not, but needs several seeds (8: a t distribution of 7 degrees of freedom per
block).  Printed: the share of blocks beyond |z| = 4, the extreme z and their spread, the worst blocks, and for each
``--region NAME:ROW0:ROW1:COL0:COL1`` (pixels) the luminance mean's relative difference pooled over the region
and the seeds, with its z.  decisions.md 134 used it (as scratch code) to find that the peer scene's 256-spp block
z was Mitsuba's ray offset.  ``--save DIR`` keeps each seed's image (``.npy``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "src"))


def blocks(image: np.ndarray, block: int) -> np.ndarray:
    """Block means (H / block, W / block, 3) of an image (H, W, 3); the last partial rows and columns left out."""
    h, w = image.shape[0] // block, image.shape[1] // block
    return image[: h * block, : w * block].reshape(h, block, w, block, -1).mean(axis=(1, 3))


def block_z(images: np.ndarray, ref_mean: np.ndarray, ref_variance: np.ndarray, block: int) -> np.ndarray:
    """Each block's z per channel: the seeds' block means against the reference's, with the variance of the seeds'
    mean from their spread and the reference's from its passes plus (2e-4 ref)^2 + 1e-4^2 per pixel (float32
    round-off of Mitsuba's film, as suite.py's pooled z), both averaged over the block's pixels."""
    from suite import ABSOLUTE

    seeds = images.shape[0]
    means = np.array([blocks(image, block) for image in images])
    lp_var = means.var(axis=0, ddof=1) / seeds
    ref_var = blocks(ref_variance + (2e-4 * ref_mean) ** 2 + ABSOLUTE**2, block) / block**2
    return (means.mean(axis=0) - blocks(ref_mean, block)) / np.sqrt(lp_var + ref_var + 1e-300)


def region_difference(images: np.ndarray, ref_mean: np.ndarray, ref_variance: np.ndarray, rows, cols) -> dict:
    """The luminance mean over a region, lightprobe's seeds against the reference: relative difference and z."""
    from lightprobe.color import LUMINANCE_WEIGHTS as LUMINANCE

    per_seed = (images[:, rows, cols] @ LUMINANCE).mean(axis=(1, 2))
    ref = float((ref_mean[rows, cols] @ LUMINANCE).mean())
    n = ref_mean[rows, cols].shape[0] * ref_mean[rows, cols].shape[1]
    var = per_seed.var(ddof=1) / per_seed.size + float((ref_variance[rows, cols] @ LUMINANCE**2).sum()) / n**2
    mean = float(per_seed.mean())
    return {"relative": mean / ref - 1.0, "sigma": float(np.sqrt(var)) / ref, "z": (mean - ref) / float(np.sqrt(var))}


def parse_region(text: str) -> tuple[str, slice, slice]:
    try:
        name, r0, r1, c0, c1 = text.split(":")
        return name, slice(int(r0), int(r1)), slice(int(c0), int(c1))
    except ValueError:
        raise SystemExit(f"--region {text!r}: expected NAME:ROW0:ROW1:COL0:COL1 (pixels)") from None


def main() -> int:
    import suite
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.reference_scenes import SUITE, build

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", choices=SUITE, default="peer")
    parser.add_argument("--spp", type=int, default=512)
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--resolution", type=int, nargs=2, default=[320, 240])
    parser.add_argument("--cache", default=str(Path.home() / ".cache" / "lightprobe-suite"))
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="a RenderSettings field (repeatable)")  # fmt: skip
    parser.add_argument("--block", type=int, default=8)
    parser.add_argument("--region", action="append", default=[], metavar="NAME:ROW0:ROW1:COL0:COL1")
    parser.add_argument("--save", metavar="DIR", help="keep each seed's image here")
    args = parser.parse_args()
    if args.seeds < 2:
        parser.error("--seeds: at least 2 (the errors come from the spread between seeds; 8 or more is better)")
    regions = [parse_region(text) for text in args.region]
    path = suite.reference_file(Path(args.cache), args.scene, args.resolution)
    if not path.exists():
        raise SystemExit(f"no reference for {args.scene} at {args.resolution[0]} x {args.resolution[1]} in {path}: "
                         f"make one with benchmarks/suite.py --worker reference --scene {args.scene}")  # fmt: skip
    ref = suite.load_reference(path)
    options = suite.parse_options(args.option)
    images = []
    for s in range(args.seeds):
        start = time.perf_counter()
        result = render(build(args.scene, resolution=tuple(args.resolution)),
                        RenderSettings(spp=args.spp, seed=100 + s, **options))  # fmt: skip
        images.append(result.image.astype(np.float64))
        print(f"seed {100 + s}: {time.perf_counter() - start:.1f} s", flush=True)
        if args.save:
            Path(args.save).mkdir(parents=True, exist_ok=True)
            np.save(Path(args.save) / f"{args.scene}_{args.spp}spp_seed{100 + s}.npy", images[-1])
    images = np.array(images)
    if args.seeds < 8:
        print(f"note: {args.seeds} seeds give each block's variance {args.seeds - 1} degree(s) of freedom: "
              "|z| > 4 is common by chance; use 8 or more", flush=True)  # fmt: skip
    z = block_z(images, ref["mean"], ref["variance"], args.block)
    summary = {"scene": args.scene, "spp": args.spp, "seeds": args.seeds, "options": options,
               "reference_spp": ref["spp"], "reference_floor": ref["floor"], "blocks": int(z[..., 0].size),
               "over4": float(np.mean(np.abs(z) > 4.0)), "z_min": float(z.min()), "z_max": float(z.max()),
               "z_sd": float(z.std())}  # fmt: skip
    for name, rows, cols in regions:
        summary[f"region_{name}"] = region_difference(images, ref["mean"], ref["variance"], rows, cols)
    print(json.dumps(summary), flush=True)
    print(f"blocks beyond |z| = 4: {100 * summary['over4']:.2f} % of {summary['blocks']} (x 3 channels); "
          f"z from {summary['z_min']:+.1f} to {summary['z_max']:+.1f}, sd {summary['z_sd']:.2f}")  # fmt: skip
    worst = np.argsort(np.abs(z).max(axis=-1).ravel())[::-1][:6]
    for i in worst:
        y, x = np.unravel_index(i, z.shape[:2])
        print(f"  block row {y}, column {x} (pixels {y * args.block}.., {x * args.block}..): z {np.round(z[y, x], 1)}")
    for name, _rows, _cols in regions:
        r = summary[f"region_{name}"]
        print(f"  region {name}: {100 * r['relative']:+.4f} % +- {100 * r['sigma']:.4f} %, z {r['z']:+.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
