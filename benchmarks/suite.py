#!/usr/bin/env python3
"""Benchmark suite: lightprobe's defaults against Mitsuba 3's and Blender Cycles' configurations on nine varied scenes
(issue 57).

    pip install -e '.[peers]'                      # Mitsuba 3.9.1 (Debian: apt-get install libllvm19)
    python benchmarks/suite.py                     # every scene of reference_scenes.SUITE at 16, 64 and 256 spp
    python benchmarks/suite.py --scenes building window --spp 16 64 --seeds 2
    python benchmarks/suite.py --lightprobe-option outline_control_variate=false   # judge a setting on the suite
    python benchmarks/suite.py --quick             # a cheap smoke run: 16 spp, one seed, small references
    python benchmarks/suite.py --write-docs        # and write the table into docs/performance.md

Scenes: :data:`lightprobe.reference_scenes.SUITE`, each described once (``reference_scenes.describe``) and built by
lightprobe (``reference_scenes.build``) and by Mitsuba (``mitsuba_references.scene_dict``; the peer scene by the peer
kit's own ``render.py``), 320 x 240.  A scene that cannot be built here (``gltf`` without ``../shared/data``) is
skipped with one line saying why.

References: Mitsuba's ``direct`` integrator (:data:`REFERENCE`: ``multijitter``, 1 + 1 emitter + BSDF samples, with
power-weighted emitters on the many-light scenes; 4 + 4 on the peer scene, as its kit's reference), in independent
passes of 64 spp, kept as running sums (so a reference can be extended) in ``--cache`` (default
``~/.cache/lightprobe-suite``), outside the repository.  The rule: the reference's relMSE floor,
mean(var_ref / (ref^2 + 0.01)) with var_ref the variance of its mean (never below the emitters' outline variance
L^2 a (1 - a) / spp, :func:`outline_variance`), must be at most a tenth of the smallest error it judges,
lightprobe's at the highest spp of the run.  Before a reference is made, lightprobe renders a pilot image at that
spp (one seed), and passes are added until the floor is below 0.07 x the pilot's relMSE against the
reference so far (or ``--reference-minutes`` run out; a later run with more minutes adds passes).  The table prints
the floor and the ratio floor / lightprobe's measured error; a scene whose ratio is above 0.1 is reported as refused,
with no ratio.

Runs: per scene and spp, Mitsuba renders every sampler (independent, stratified, multijitter, ldsampler) at 1 + 1
and 4 + 4 (``direct``'s ``emitter_samples`` / ``bsdf_samples``; on many-light scenes also with each emitter's
``sampling_weight`` = its power, "power"), lightprobe its defaults (with ``--lightprobe-option`` settings), in
alternating subprocesses (Mitsuba, lightprobe, Mitsuba, ... as lights_vs_mitsuba.py does), ``--seeds`` images each:
relMSE is the mean over the seeds, seconds the median of each renderer's own render time (kernels compiled first:
Mitsuba renders once with another seed, lightprobe renders the scene once at 4 spp).  Efficiency = 1 / (relMSE x
seconds); the ratio is lightprobe's over the best peer configuration's; time per camera sample = seconds /
(pixels x spp).  Pooled z (lightprobe's seeds averaged against the reference): per pixel and channel
z = (lp - ref) / sqrt(var_lp + var_ref), var_lp never below the reference's per-sample variance at lightprobe's
count (a rare bright event none of lightprobe's samples met leaves its own estimate too low; as
tests/integrators/test_references.py; plus (2e-4 ref)^2 for float32 round-off and 1e-4^2 absolute, a thousandth of
the relMSE's scale), pooled as sum(lp - ref) / sqrt(sum(var)) over the image (per channel: the largest |z|) and
over 8 x 8-pixel blocks (the largest |z| and the share of blocks beyond |z| = 4, about 6e-5 for an unbiased image).
Then the minimum and the geometric mean of the ratios.  Benchmarks print figures; they never assert speed.

``--spread``: no references at all.  Every configuration's relMSE is its variance, measured from the spread
between its seeds (``--seeds``, at least 2: the sample variance of each pixel, for two half their squared
difference, over (m^2 + 0.01), where m is the mean of every render of the scene, each weighted by its spp;
averaged over the pixels and channels), which is its MSE because every
configuration compared is unbiased (lightprobe's and Mitsuba's are z-tested against each other in tests/, and here
again: lightprobe's seeds' mean against the mean of all of Mitsuba's renders of the scene, with the variances the
seeds give; the blocks' z is only indicative there: a pixel's variance from two seeds is mostly too small where
a rare bright sample decides it).  It has no floor, so it needs no hours of reference on a fresh machine: the
suite at 16 and 64 spp runs in about an hour.  The images are kept in ``--cache``/spread until the scene's metrics
are made.  Cycles is left out (its conductors converge to another image, whose bias the spread cannot see).

Blender Cycles (``bpy``), the second peer, where its light tree should make it the stronger one: a Python with
``bpy`` (``--cycles-python``, else $LIGHTPROBE_CYCLES_PYTHON, else :data:`CYCLES_PYTHON` if it exists; none: the
suite says so once and goes on without Cycles).  The suite's Python writes each scene's description as plain
arrays into the cache (benchmarks/cycles_scene.py ``export``; the peer kit's scene and the glTF asset are not
translated and say so) and the Cycles workers, run under that Python, build it in Blender (``cycles_scene.build``).
Configurations (:data:`CYCLES_CONFIGS`): the light tree on and off, each with one light sample and one BSDF sample
per camera sample (``max_bounces`` 0: direct light only, MIS), a box filter 1 pixel wide, 2 threads, no denoising,
adaptive sampling, clamping or light threshold, seeds 1, 2, ... after an untimed render.  Seconds = the median
path-tracing time (Cycles' first "Sample" status line to "Finished", as ``../shared/peers/cycles/render.py``
measures it), without bpy's import, the scene build or the scene sync every render does (``sync_s``, printed).
Cycles' GGX conductor need not converge to Mitsuba's image, so a Cycles row's relMSE is measured against a **Cycles
reference** (light tree on, passes of :data:`CYCLES_PASS_SPP`, at least :data:`CYCLES_MIN_PASSES`, grown as
Mitsuba's are until its floor is at most 0.07 x the relMSE of a Cycles pilot image at the run's highest spp; a
Cycles row whose reference's floor is above a tenth of its error is listed, marked, but never the best peer); the
two references are compared with each other per scene (:func:`reference_agreement`: relMSE and pooled z, over the
image and over the pixels where no rough conductor is seen), the translation's check.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MITSUBA_SAMPLERS = ("independent", "stratified", "multijitter", "ldsampler")
MANY_LIGHTS = ("ceiling", "dome", "building", "city")  # Mitsuba also with power-weighted emitters
PASS_SPP = 64  # a reference pass (Mitsuba's llvm variant keeps one wavefront of pixels x spp lanes in memory)
# scene -> (sampler, emitter + BSDF samples each, power-weighted emitters) of its reference
REFERENCE = {
    "peer": ("multijitter", 4, False),
    **{name: ("multijitter", 1, name in MANY_LIGHTS) for name in
       ("area", "ceiling", "dome", "window", "building", "gltf", "glossy", "city")},
}  # fmt: skip
FLOOR_RULE = 0.1  # the reference's floor at most this share of the smallest error it judges
REFERENCE_MARGIN = 0.07  # a reference grows until its floor is this share of the pilot's error (one seed's)
BLOCK = 8
ABSOLUTE = 1e-4  # the pooled z's absolute tolerance per pixel and channel
DOCS_BEGIN, DOCS_END = "<!-- suite:begin -->", "<!-- suite:end -->"
# Blender Cycles (bpy), the second peer: its configurations (light tree on / off), its reference passes
CYCLES_CONFIGS = (("tree", True), ("notree", False))
CYCLES_PASS_SPP = 256  # a Cycles reference pass (its sampler is a QMC sequence: longer passes converge faster)
CYCLES_MIN_PASSES = 8
CYCLES_PYTHON = "/work/bpyvenv/bin/python"  # the default bpy interpreter (Python 3.11, pip install bpy==5.0.1)


# ----------------------------------------------------------------------------------------------- shared helpers


def relmse(image, ref) -> float:
    """mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01): the project's metric."""
    x, r = np.asarray(image, np.float64), np.asarray(ref, np.float64)
    return float(np.mean((x - r) ** 2 / (r**2 + 0.01)))


def reference_file(cache: Path, scene: str, resolution) -> Path:
    w, h = resolution
    sampler, n, power = REFERENCE[scene]
    return cache / f"{scene}_{w}x{h}_{sampler}_{n}+{n}{'_power' if power else ''}.npz"


def outline_variance(scene) -> np.ndarray:
    """(H, W, 3) a lower bound on one camera sample's variance from the emitters seen directly: where an emitter of
    radiance L covers a share a of a pixel, a sample meets it with probability a, so its variance is at least
    L^2 a (1 - a).  A reference's own estimate misses it where none of its samples met a sliver of a bright light
    (the glossy scene's 5,000-radiance sphere covering 0.2 % of a pixel: 0 hits in 1,024 spp, a mean of 0.01 where
    the truth is 9.9), and lightprobe's outline control variate knows the exact L a there: the reference's noise,
    not lightprobe's, would then be most of lightprobe's measured error (decision 99).  From lightprobe's outline
    table (integrators/outlines.py: the exact coverage of each pixel by each emitter), as
    tests/integrators/test_references.py does; an emitter counts in a pixel only if its nearest point is nearer
    than what the ray through the pixel's centre meets (the table ignores occlusion: a light behind a wall would
    count in every pixel of the wall)."""
    from lightprobe.emitters.kinds import LIGHT_RECT, LIGHT_SPHERE, LIGHT_TRIANGLE
    from lightprobe.geometry.raytracer import RayTracer
    from lightprobe.integrators import outlines

    w, h = scene.camera.resolution
    floor = np.zeros((w * h, 3))
    lights = scene.light_table()
    if lights.kind.size == 0:
        return floor.reshape(h, w, 3)
    table = outlines.table(scene.camera, lights, None)  # the geometry alone: occlusion is judged below
    if table.start.size == 0 or table.shape.size == 0:
        return floor.reshape(h, w, 3)
    # each light's centre and the radius of a ball around it that holds it
    g = lights.geom
    centre, radius = np.zeros((g.shape[0], 3)), np.zeros(g.shape[0])
    rect, sphere, tri = lights.kind == LIGHT_RECT, lights.kind == LIGHT_SPHERE, lights.kind == LIGHT_TRIANGLE
    centre[rect] = g[rect, 0:3] + (g[rect, 3:6] + g[rect, 6:9]) / 2
    radius[rect] = (
        np.linalg.norm(g[rect, 3:6] + g[rect, 6:9], axis=1) / 2
        + np.linalg.norm(g[rect, 3:6] - g[rect, 6:9], axis=1) / 2
    )
    centre[sphere], radius[sphere] = g[sphere, 0:3], g[sphere, 3]
    corners = g[tri, 0:9].reshape(-1, 3, 3)
    centre[tri] = corners.mean(axis=1)
    radius[tri] = np.linalg.norm(corners - centre[tri][:, None, :], axis=2).max(axis=1)
    pixels_all = np.arange(w * h)
    origins, dirs = scene.camera.rays(pixels_all, np.full((pixels_all.size, 2), 0.5))
    tracer = RayTracer(scene.compile())
    try:
        t, *_ = tracer.intersect(origins, dirs)
    finally:
        tracer.close()
    pixels = np.repeat(pixels_all, np.diff(table.start))
    # the table names its shapes by their outline geometry: find each one's row of the light table
    found = outlines._shapes(outlines._Film(scene.camera), lights)
    row_of = {r.tobytes(): int(found.light[i]) for i, r in enumerate(found.rows)}
    light = np.array([row_of[r.tobytes()] for r in table.geom], np.int64)[table.shape]
    nearest = np.linalg.norm(centre[light] - origins[pixels], axis=1) - radius[light]
    seen = nearest <= t[pixels] * (1.0 + 1e-6) + 1e-6
    radiance = table.radiance[table.shape]
    np.add.at(floor, pixels[seen], (radiance**2 * (table.cover * (1.0 - table.cover))[:, None])[seen])
    return floor.reshape(h, w, 3)


def load_reference(path: Path) -> dict:
    """mean (H, W, 3), variance of the mean (never below the emitters' outline variance / spp), spp, passes,
    seconds and floor of a reference's running sums."""
    with np.load(path) as f:
        total, total2, passes = f["total"], f["total2"], int(f["passes"])
        seconds, pass_spp = float(f["seconds"]), int(f["pass_spp"])
        outline = f["outline"] if "outline" in f else 0.0
    mean = total / passes
    variance = np.maximum(total2 / passes - mean**2, 0.0) * passes / (passes - 1) / passes
    variance = np.maximum(variance, outline / (passes * pass_spp))
    floor = float(np.mean(variance / (mean**2 + 0.01)))
    return {"mean": mean, "variance": variance, "spp": passes * pass_spp, "passes": passes, "seconds": seconds,
            "floor": floor}  # fmt: skip


def pooled_z(images: list[np.ndarray], variances: list[np.ndarray], spp: int, ref: dict) -> dict:
    """The pooled z of lightprobe's seeds (averaged) against the reference: the image's (largest |z| of the three
    channels), and over 8 x 8 blocks the largest |z| and the share beyond 4.  See the module docstring."""
    k = len(images)
    mean = np.mean(images, axis=0).astype(np.float64)
    var = np.sum(variances, axis=0).astype(np.float64) / k**2
    var_ref = ref["variance"]
    var = np.maximum(var, var_ref * ref["spp"] / (spp * k))  # never below the reference's per-sample variance
    # 2e-4 relative: float32 round-off where neither image has noise (a constant sky seen directly); 1e-4 absolute,
    # a thousandth of the relMSE's scale (0.1): in pixels darker than that (a sky's sliver in a shadow) a rare event
    # none of lightprobe's samples met leaves both variance estimates far too small, and a block of them a false z
    diff = mean - ref["mean"]
    total = var + var_ref + (2e-4 * ref["mean"]) ** 2 + ABSOLUTE**2
    return _z(diff, total)


def _z(diff: np.ndarray, total: np.ndarray) -> dict:
    """The pooled z of a difference of images (H, W, 3) with the variance ``total`` of each pixel's difference:
    the image's (the channel of largest |z|), and over 8 x 8 blocks the largest |z| and the share beyond 4."""
    image_z = diff.sum(axis=(0, 1)) / np.sqrt(total.sum(axis=(0, 1)))
    h, w = diff.shape[:2]
    hb, wb = h // BLOCK, w // BLOCK
    d = diff[: hb * BLOCK, : wb * BLOCK].reshape(hb, BLOCK, wb, BLOCK, 3).sum(axis=(1, 3, 4))
    v = total[: hb * BLOCK, : wb * BLOCK].reshape(hb, BLOCK, wb, BLOCK, 3).sum(axis=(1, 3, 4))
    block_z = d / np.sqrt(v)
    return {
        "z_image": float(image_z[np.argmax(np.abs(image_z))]),
        "z_blocks_max": float(np.abs(block_z).max()),
        "z_blocks_over4": float(np.mean(np.abs(block_z) > 4.0)),
    }


def spread_dir(cache, scene: str, resolution, spp: int) -> Path:
    """Where ``--spread``'s workers keep a scene's images at ``spp`` until the parent has measured them."""
    w, h = resolution
    return Path(cache) / "spread" / f"{scene}_{w}x{h}_{spp}spp"


def _seed_variance(images: list[np.ndarray]) -> np.ndarray:
    """Each pixel's variance of one image, from independent images of it (the sample variance: for two, half
    their squared difference)."""
    return np.var(np.stack(images), axis=0, ddof=1)


def spread_metrics(rows: list[dict]) -> list[dict]:
    """``--spread``'s rows of one scene (their ``images``: the files of their seeds' images) with relMSE, the
    variance between seeds over (m^2 + 0.01), m the mean of every image weighted by its spp, and efficiency; the
    lightprobe rows also with the pooled z of their seeds' mean against the mean of Mitsuba's images (every
    configuration and spp, each image's variance from its configuration's seeds).  The files are then removed."""
    images = {id(row): [np.load(f).astype(np.float64) for f in row["images"]] for row in rows}
    weight = sum(row["spp"] * len(images[id(row)]) for row in rows)
    mean = sum(row["spp"] * sum(images[id(row)]) for row in rows) / weight
    variance = {id(row): _seed_variance(images[id(row)]) for row in rows}
    peers = [row for row in rows if row["renderer"] == "mitsuba"]
    peer_images = sum(len(images[id(row)]) for row in peers)
    out = []
    for row in rows:
        done = {k: v for k, v in row.items() if k != "images"}
        done["relmse"] = float(np.mean(variance[id(row)] / (mean * mean + 0.01)))
        done["efficiency"] = 1.0 / (done["relmse"] * done["seconds"])
        if row["renderer"] == "lightprobe" and peers:
            mine = images[id(row)]
            peer_mean = sum(sum(images[id(p)]) for p in peers) / peer_images
            peer_var = sum(len(images[id(p)]) * variance[id(p)] for p in peers) / peer_images**2
            diff = np.mean(mine, axis=0) - peer_mean
            total = variance[id(row)] / len(mine) + peer_var + (2e-4 * mean) ** 2 + ABSOLUTE**2
            done |= _z(diff, total)
        out.append(done)
    for row in rows:
        for f in row["images"]:
            Path(f).unlink(missing_ok=True)
    return out


def _keep(args, renderer: str, config: str, seed: int, image) -> str:
    """``--spread``: an image kept for the parent (float32 .npy); its path."""
    folder = spread_dir(args.cache, args.scene, args.resolution, args.spp)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{renderer}_{config.replace(' ', '_').replace('+', 'p')}_{seed}.npy"
    np.save(path, np.asarray(image, np.float32))
    return str(path)


def parse_options(pairs: list[str]) -> dict:
    """``KEY=VALUE`` settings of lightprobe's RenderSettings, the values read as JSON (true, 2, 0.5, "power") or
    else as strings."""
    options = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep:
            raise SystemExit(f"--lightprobe-option {pair!r}: expected KEY=VALUE")
        try:
            options[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            options[key.strip()] = value
    return options


# ---------------------------------------------------------------------------------------------- the table code


def summarise(rows: list[dict], references: dict) -> list[dict]:
    """Per (scene, spp): lightprobe's row, the best peer configuration (Mitsuba's or Cycles'), the ratio of
    efficiencies, and the floor rule (``refused`` when the reference's floor exceeds a tenth of lightprobe's error;
    a peer row whose own reference fails the rule, a Cycles row with ``floor_ratio`` above it, is listed but never
    the best)."""
    out = []
    keys = sorted({(r["scene"], r["spp"]) for r in rows}, key=lambda k: (k[0], k[1]))
    for scene, spp in keys:
        mine = [r for r in rows if r["scene"] == scene and r["spp"] == spp]
        ours = next((r for r in mine if r["renderer"] == "lightprobe"), None)
        peers = [r for r in mine if r["renderer"] != "lightprobe"]
        judged = [r for r in peers if (r.get("floor_ratio") or 0.0) <= FLOOR_RULE]
        if ours is None or not judged:
            continue
        best = max(judged, key=lambda r: r["efficiency"])
        floor = references.get(scene, {}).get("floor")
        floor_ratio = floor / ours["relmse"] if floor is not None and ours["relmse"] > 0 else None
        refused = floor_ratio is not None and floor_ratio > FLOOR_RULE
        out.append({
            "scene": scene, "spp": spp, "lightprobe": ours, "best": best, "peers": peers,
            "ratio": None if refused else ours["efficiency"] / best["efficiency"],
            "floor": floor, "floor_ratio": floor_ratio, "refused": refused,
        })  # fmt: skip
    return out


def ratio_stats(ratios) -> tuple[float | None, float | None]:
    """(minimum, geometric mean) of the ratios that are numbers; (None, None) without any."""
    values = [r for r in ratios if r is not None and r > 0 and math.isfinite(r)]
    if not values:
        return None, None
    return min(values), math.exp(sum(math.log(r) for r in values) / len(values))


def _f(x, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def table(summary: list[dict], pixels: int) -> str:
    """The suite's table (Markdown)."""
    lines = [
        "| scene | spp | lightprobe s | relMSE | efficiency | best peer configuration | s | relMSE | efficiency "
        "| ratio | ns per camera sample, lp / peer | M samples/s, lp / peer | pooled z (image; blocks max, "
        "share > 4) | reference floor (/ lp error) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summary:
        lp, best = s["lightprobe"], s["best"]
        n = pixels * s["spp"]
        z = (f"{lp['z_image']:+.1f}; {lp['z_blocks_max']:.1f}, {lp['z_blocks_over4']:.3f}"
             if "z_image" in lp else "-")  # fmt: skip
        ratio = "refused (floor)" if s["refused"] else f"**{s['ratio']:.2f}x**"
        lines.append(
            f"| {s['scene']} | {s['spp']} | {lp['seconds']:.2f} | {lp['relmse']:.3g} | {lp['efficiency']:.3g} | "
            f"{best['config']} | {best['seconds']:.2f} | {best['relmse']:.3g} | {best['efficiency']:.3g} | {ratio} | "
            f"{1e9 * lp['seconds'] / n:.0f} / {1e9 * best['seconds'] / n:.0f} | "
            f"{n / lp['seconds'] / 1e6:.2f} / {n / best['seconds'] / 1e6:.2f} | {z} | "
            f"{_f(s['floor'], '.2g')} ({_f(s['floor_ratio'], '.3f')}) |"
        )
    lo, geo = ratio_stats([s["ratio"] for s in summary])
    lines.append("")
    lines.append(f"Ratio of efficiencies, lightprobe / best peer configuration: minimum {_f(lo, '.2f')}x, "
                 f"geometric mean {_f(geo, '.2f')}x over {sum(s['ratio'] is not None for s in summary)} "
                 "scene x spp rows.")  # fmt: skip
    return "\n".join(lines)


def peer_table(summary: list[dict]) -> str:
    """Every configuration's efficiency per (scene, spp), lightprobe's, Mitsuba's and Cycles' (Markdown; a Cycles
    row whose reference fails the floor rule is marked *)."""
    configs = sorted({r["config"] for s in summary for r in s["peers"]},
                     key=lambda c: (c.startswith("cycles"), c.count("power"), c))  # fmt: skip
    lines = ["| scene | spp | lightprobe | " + " | ".join(configs) + " |", "|---" * (3 + len(configs)) + "|"]
    for s in summary:
        eff = {r["config"]: r["efficiency"] for r in s["peers"]}
        refused = {r["config"] for r in s["peers"] if (r.get("floor_ratio") or 0.0) > FLOOR_RULE}
        cells = [_f(eff.get(c), ".3g") + ("*" if c in refused else "") for c in configs]
        lines.append(f"| {s['scene']} | {s['spp']} | {s['lightprobe']['efficiency']:.3g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_docs(text: str, path: Path = ROOT / "docs" / "performance.md") -> None:
    """Put ``text`` between the suite's markers in docs/performance.md (replacing what was there)."""
    doc = path.read_text()
    if DOCS_BEGIN not in doc or DOCS_END not in doc:
        raise SystemExit(f"{path}: no {DOCS_BEGIN} / {DOCS_END} markers")
    head, rest = doc.split(DOCS_BEGIN, 1)
    _, tail = rest.split(DOCS_END, 1)
    path.write_text(f"{head}{DOCS_BEGIN}\n{text}\n{DOCS_END}{tail}")


# ----------------------------------------------------------------------------------------------------- workers


def _mitsuba_references():
    """benchmarks/mitsuba_references.py (imports neither Mitsuba nor Dr.Jit)."""
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    import mitsuba_references

    return mitsuba_references


def _mitsuba():
    mr = _mitsuba_references()

    mr._prefer_llvm19()
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    import mitsuba_gltf

    mitsuba_gltf.register(mi, dr)
    return mi, mr


def _mitsuba_scene(mi, mr, scene: str, resolution, tmp: str, *, power: bool, spp: int) -> dict:
    """Mitsuba's scene dict of a suite scene (integrator and sampler set by the caller)."""
    if scene == "peer":
        from lightprobe.peer import find_peers

        kit = find_peers()
        sys.path.insert(0, str(kit / "mitsuba"))
        import render as kit_render

        assets = Path(os.environ["LIGHTPROBE_SUITE_CACHE"]) / "peer_assets"
        if not (assets / "env.exr").exists():  # the kit's deterministic assets, made once into the cache
            subprocess.run([sys.executable, str(kit / "mitsuba" / "scene_assets.py"), str(assets)], check=True,
                           capture_output=True)  # fmt: skip
        spec = kit_render.load_spec()
        d = kit_render.scene_dict(mi, spec, str(assets), "direct_mis", resolution[0], spp)
        d["sensor"]["film"]["width"], d["sensor"]["film"]["height"] = resolution
        return d
    import lightprobe.reference_scenes as rs
    from lightprobe.images import write_image

    desc = rs.describe(scene)
    env_file = None
    image = rs.environment_image(desc)
    if image is not None:
        env_file = str(Path(tmp) / "env.exr")
        write_image(env_file, image)
    return mr.scene_dict(mi, desc, env_file, spp, tmp, power_weights=power, resolution=tuple(resolution))


def _sensor(mi, d: dict, sampler: str, spp: int):
    sensor = dict(d["sensor"])
    sensor["sampler"] = {"type": sampler, "sample_count": spp}
    return mi.load_dict(sensor)


def _integrator(mi, n: int):
    return mi.load_dict({"type": "direct", "emitter_samples": n, "bsdf_samples": n})


def _running_sums(path: Path) -> tuple:
    """(sum, sum of squares, passes, seconds) of a reference kept at ``path`` (Mitsuba's or Cycles'), zeros when
    there is none yet: a reference grows from where an earlier run left it."""
    if not path.exists():
        return 0.0, 0.0, 0, 0.0
    with np.load(path) as f:
        return f["total"], f["total2"], int(f["passes"]), float(f["seconds"])


def mitsuba_reference(args) -> None:
    """Add passes to the scene's reference until its floor is at most :data:`REFERENCE_MARGIN` x the relMSE of
    lightprobe's pilot image against it (``--pilot``; at least 16 passes), or ``--reference-minutes`` have passed;
    print one JSON line."""
    mi, mr = _mitsuba()
    out = reference_file(Path(args.cache), args.scene, args.resolution)
    pilot = np.load(args.pilot) if args.pilot else None
    sampler, n, power = REFERENCE[args.scene]
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        d = _mitsuba_scene(mi, mr, args.scene, args.resolution, tmp, power=power, spp=PASS_SPP)
        d["integrator"] = {"type": "direct", "emitter_samples": n, "bsdf_samples": n}
        d["sensor"]["sampler"] = {"type": sampler, "sample_count": PASS_SPP}
        scene = mi.load_dict(d)
        load = time.perf_counter() - start
        outline = outline_variance(_lightprobe_build(args))
        total, total2, passes, seconds = _running_sums(out)
        start = time.perf_counter()
        floor = error = math.inf
        while True:
            if passes >= 16 and passes % 8 == 0:
                mean = total / passes
                var = np.maximum(total2 / passes - mean**2, 0.0) / (passes - 1)
                var = np.maximum(var, outline / (passes * PASS_SPP))
                floor = float(np.mean(var / (mean**2 + 0.01)))
                error = relmse(pilot, mean) if pilot is not None else 0.0
                elapsed = time.perf_counter() - start
                np.savez(out, total=total, total2=total2, passes=passes, pass_spp=PASS_SPP,
                         seconds=seconds + elapsed, outline=outline)  # fmt: skip
                if floor <= REFERENCE_MARGIN * error or elapsed > 60 * args.reference_minutes:
                    break
            x = np.array(mi.render(scene, spp=PASS_SPP, seed=1_000_003 * (passes + 1)), dtype=np.float64)
            total, total2, passes = total + x, total2 + x * x, passes + 1
        seconds += time.perf_counter() - start
        np.savez(out, total=total, total2=total2, passes=passes, pass_spp=PASS_SPP, seconds=seconds, outline=outline)
    print(json.dumps({"reference": args.scene, "spp": passes * PASS_SPP, "seconds": round(seconds, 1),
                      "floor": floor, "pilot_relmse": error, "load_s": round(load, 2),
                      "config": f"{sampler} {n}+{n}{' power' if power else ''}"}), flush=True)  # fmt: skip


def mitsuba_runs(args) -> None:
    """Every Mitsuba configuration at ``--spp``, ``--seeds`` images each: one JSON line per configuration."""
    mi, mr = _mitsuba()
    ref = None if args.spread else load_reference(reference_file(Path(args.cache), args.scene, args.resolution))
    weightings = (False, True) if args.scene in MANY_LIGHTS else (False,)
    with tempfile.TemporaryDirectory() as tmp:
        for power in weightings:
            start = time.perf_counter()
            d = _mitsuba_scene(mi, mr, args.scene, args.resolution, tmp, power=power, spp=args.spp)
            scene = mi.load_dict(d)
            load = time.perf_counter() - start
            for sampler in MITSUBA_SAMPLERS:
                sensor = _sensor(mi, d, sampler, args.spp)
                for n in (1, 4):
                    integrator = _integrator(mi, n)
                    mi.render(scene, sensor=sensor, integrator=integrator, spp=args.spp, seed=10_000)  # compile
                    errors, seconds, kept = [], [], []
                    config = f"{sampler} {n}+{n}" + (" power" if power else "")
                    for s in range(args.seeds):
                        begin = time.perf_counter()
                        image = mi.render(scene, sensor=sensor, integrator=integrator, spp=args.spp, seed=s + 1)
                        x = np.array(image, dtype=np.float64)
                        seconds.append(time.perf_counter() - begin)
                        if ref is None:
                            kept.append(_keep(args, "mitsuba", config, s, x))
                        else:
                            errors.append(relmse(x, ref["mean"]))
                    t = float(np.median(seconds))
                    row = {"renderer": "mitsuba", "scene": args.scene, "spp": args.spp, "config": config,
                           "seconds": t, "load_s": round(load, 2)}  # fmt: skip
                    if ref is None:
                        row["images"] = kept
                    else:
                        e = float(np.mean(errors))
                        row |= {"relmse": e, "efficiency": 1.0 / (e * t)}
                    print(json.dumps(row), flush=True)


def _lightprobe_build(args):
    sys.path.insert(0, str(ROOT / "src"))
    from lightprobe.reference_scenes import build

    return build(args.scene, resolution=tuple(args.resolution))


def lightprobe_pilot(args) -> None:
    """lightprobe's defaults at ``--spp`` once (seed 999), its image saved for the reference's rule."""
    from lightprobe.integrators.wavefront import RenderSettings, render

    scene = _lightprobe_build(args)
    r = render(scene, RenderSettings(spp=args.spp, seed=999, **parse_options(args.lightprobe_option)))
    np.save(args.pilot, r.image.astype(np.float64))
    print(json.dumps({"pilot": args.scene, "spp": args.spp, "seconds": r.stats["seconds"]}), flush=True)


def lightprobe_runs(args) -> None:
    """lightprobe's defaults (and ``--lightprobe-option``) at ``--spp``, ``--seeds`` images: one JSON line."""
    from lightprobe.integrators.wavefront import RenderSettings, render

    options = parse_options(args.lightprobe_option)
    ref = None if args.spread else load_reference(reference_file(Path(args.cache), args.scene, args.resolution))
    scene = _lightprobe_build(args)
    render(scene, RenderSettings(spp=4, seed=10_000, **options))  # compile
    errors, seconds, images, variances, kept = [], [], [], [], []
    for s in range(args.seeds):
        r = render(_lightprobe_build(args), RenderSettings(spp=args.spp, seed=s + 20, **options))
        images.append(r.image.astype(np.float64))
        variances.append(r.variance.astype(np.float64))
        seconds.append(r.stats["seconds"])
        if ref is None:
            kept.append(_keep(args, "lightprobe", "defaults", s, images[-1]))
        else:
            errors.append(relmse(images[-1], ref["mean"]))
    t = float(np.median(seconds))
    row = {"renderer": "lightprobe", "scene": args.scene, "spp": args.spp, "config": "defaults", "seconds": t,
           "options": options}  # fmt: skip
    if ref is None:
        row["images"] = kept
    else:
        e = float(np.mean(errors))
        row |= {"relmse": e, "efficiency": 1.0 / (e * t)} | pooled_z(images, variances, args.spp, ref)
    print(json.dumps(row), flush=True)


def occlusion(args) -> None:
    """The unoccluded share of the light power from the camera's visible points (scenes with < 5,000 lights)."""
    from lightprobe.reference_scenes import unoccluded_power_fraction

    scene = _lightprobe_build(args)
    if len(scene.emitters) == 0 or len(scene.emitters) > 5000:
        print(json.dumps({"occlusion": args.scene, "unoccluded": None}), flush=True)
        return
    start = time.perf_counter()
    share = unoccluded_power_fraction(scene)
    print(json.dumps({"occlusion": args.scene, "unoccluded": share, "lights": len(scene.emitters),
                      "seconds": round(time.perf_counter() - start, 1)}), flush=True)  # fmt: skip


# ------------------------------------------------------------------------------------ Blender Cycles (bpy) peer


def cycles_reference_file(cache: Path, scene: str, resolution) -> Path:
    w, h = resolution
    return cache / f"{scene}_{w}x{h}_cycles_1+1.npz"


def cycles_scene_file(cache: Path, scene: str, resolution) -> Path:
    w, h = resolution
    return cache / f"{scene}_{w}x{h}_cycles_scene.npz"


def cycles_python(option: str | None) -> tuple[str | None, str | None]:
    """(the Python with ``bpy`` to run the Cycles workers, None) or (None, why Cycles is skipped): ``--cycles-python``,
    else $LIGHTPROBE_CYCLES_PYTHON, else :data:`CYCLES_PYTHON` if it exists; it must import bpy."""
    path = option or os.environ.get("LIGHTPROBE_CYCLES_PYTHON") or CYCLES_PYTHON
    if path.lower() in ("", "none", "off"):
        return None, "turned off (--cycles-python none)"
    if not Path(path).exists():
        return None, f"no bpy Python at {path} (--cycles-python; python3.11 -m venv V && V/bin/pip install bpy==5.0.1)"
    probe = subprocess.run([path, "-c", "import bpy; print(bpy.app.version_string)"], capture_output=True, text=True)
    if probe.returncode != 0:
        return None, f"{path} cannot import bpy: {probe.stderr.strip().splitlines()[-1:]}"
    return path, None


def export_cycles_scene(cache: Path, scene: str, resolution) -> Path:
    """Write the scene's description for the Cycles workers (benchmarks/cycles_scene.py ``export``); raises
    cycles_scene.NotTranslated for a scene the translation does not make (the peer kit's scene, the glTF asset)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cycles_scene
    import lightprobe.reference_scenes as rs

    desc = rs.describe(scene)
    if desc.get("peer_kit"):
        raise cycles_scene.NotTranslated("the peer kit's scene (its rough plastic has no exact Cycles counterpart)")
    out = cycles_scene_file(cache, scene, resolution)
    env_file = None
    image = rs.environment_image(desc)
    if image is not None:
        from lightprobe.images import write_image

        env_file = str(out.with_name(out.stem + "_env.exr"))
        write_image(env_file, image)
    cycles_scene.export(desc, out, resolution=resolution, env_file=env_file)
    return out


def conductor_mask(scene: str, resolution) -> np.ndarray:
    """(H, W) True where a pixel may see a rough conductor (a sphere of one, or the bounding sphere of a mesh of one,
    grown by two pixels): Cycles' and Mitsuba's conductors need not converge to the same image; elsewhere the
    references must agree.  Pixel centres' rays from lightprobe's camera."""
    import lightprobe.reference_scenes as rs

    desc = rs.describe(scene)
    cam = rs.build(scene, resolution=tuple(resolution)).camera
    w, h = resolution
    origins, dirs = cam.rays(np.arange(w * h), np.full((w * h, 2), 0.5))
    pixel = 2.0 * math.tan(math.radians(desc["camera"]["fov"]) / 2) / w  # a pixel's width at distance 1
    mask = np.zeros(w * h, bool)
    for o in desc["objects"]:
        if "material" not in o or desc["materials"][o["material"]]["model"] == "lambertian":
            continue
        if o["shape"] == "sphere":
            c, r = np.asarray(o["center"], float), float(o["radius"])
        else:
            v = np.asarray(o["vertices"], float)
            c = v.mean(axis=0)
            r = float(np.linalg.norm(v - c, axis=1).max())
        t = np.einsum("ij,ij->i", c - origins, dirs)
        closest = np.linalg.norm(origins + t[:, None] * dirs - c, axis=1)
        mask |= closest <= r + 2.0 * pixel * np.maximum(t, 0.0)
    return mask.reshape(h, w)


def reference_agreement(cycles: dict, mitsuba: dict, mask: np.ndarray | None = None) -> dict:
    """How the Cycles reference and the Mitsuba reference of a scene agree (the translation's check): relMSE of the
    one against the other next to what their noise alone gives (mean((var_c + var_m) / (m^2 + 0.01))), the pooled
    z per channel over the image (the largest |z|), over 8 x 8 blocks (the largest |z|, the share beyond 4), the
    ratio of the image means; with ``mask`` (True: a conductor may be seen there) the same over the other pixels."""

    def measure(keep):
        c, m = cycles["mean"][keep], mitsuba["mean"][keep]
        var = cycles["variance"][keep] + mitsuba["variance"][keep] + (2e-4 * m) ** 2 + ABSOLUTE**2
        z = (c - m).sum(axis=0) / np.sqrt(var.sum(axis=0))
        return {"relmse": relmse(c, m), "noise_relmse": float(np.mean(var / (m**2 + 0.01))),
                "z_image": float(z[np.argmax(np.abs(z))]),
                "mean_ratio": [round(float(x), 5) for x in c.sum(axis=0) / np.maximum(m.sum(axis=0), 1e-300)],
                }  # fmt: skip

    h, w = cycles["mean"].shape[:2]
    out = measure(np.ones((h, w), bool))
    diff = cycles["mean"] - mitsuba["mean"]
    total = cycles["variance"] + mitsuba["variance"] + (2e-4 * mitsuba["mean"]) ** 2 + ABSOLUTE**2
    hb, wb = h // BLOCK, w // BLOCK
    d = diff[: hb * BLOCK, : wb * BLOCK].reshape(hb, BLOCK, wb, BLOCK, 3).sum(axis=(1, 3, 4))
    v = total[: hb * BLOCK, : wb * BLOCK].reshape(hb, BLOCK, wb, BLOCK, 3).sum(axis=(1, 3, 4))
    block_z = d / np.sqrt(v)
    out |= {"z_blocks_max": float(np.abs(block_z).max()), "z_blocks_over4": float(np.mean(np.abs(block_z) > 4.0))}
    if mask is not None and mask.any() and not mask.all():
        out["lambertian"] = measure(~mask) | {"pixels": int((~mask).sum())}
    return out


def _cycles_setup(args):
    """bpy and the Blender scene of ``--scene`` (from the file the suite's Python exported)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cycles_scene

    start = time.perf_counter()
    import bpy

    imported = time.perf_counter() - start
    info = cycles_scene.build(cycles_scene_file(Path(args.cache), args.scene, args.resolution))
    built = time.perf_counter() - start - imported
    clock = cycles_scene.StatsClock()
    bpy.app.handlers.render_stats.append(clock)
    return cycles_scene, clock, {"blender": bpy.app.version_string, "import_s": round(imported, 2),
                                 "build_s": round(built, 2), **info}  # fmt: skip


def cycles_reference(args) -> None:
    """Under bpy: a pilot image (light tree on, ``--spp``, seed 999), then passes of :data:`CYCLES_PASS_SPP` added to
    the scene's Cycles reference until its floor is at most :data:`REFERENCE_MARGIN` x the pilot's relMSE against it
    (at least :data:`CYCLES_MIN_PASSES` passes) or ``--reference-minutes`` have passed; one JSON line."""
    cs, clock, info = _cycles_setup(args)
    out = cycles_reference_file(Path(args.cache), args.scene, args.resolution)
    with tempfile.TemporaryDirectory() as tmp:
        cs.configure(spp=args.spp, seed=999, light_tree=True)
        pilot, _ = cs.render(clock, tmp)
        total, total2, passes, seconds = _running_sums(out)
        start = time.perf_counter()
        floor = error = math.inf
        sync = []
        while True:
            if passes >= CYCLES_MIN_PASSES and passes % 4 == 0:
                mean = total / passes
                var = np.maximum(total2 / passes - mean**2, 0.0) / (passes - 1)
                floor = float(np.mean(var / (mean**2 + 0.01)))
                error = relmse(pilot, mean)
                elapsed = time.perf_counter() - start
                np.savez(out, total=total, total2=total2, passes=passes, pass_spp=CYCLES_PASS_SPP,
                         seconds=seconds + elapsed)  # fmt: skip
                if floor <= REFERENCE_MARGIN * error or elapsed > 60 * args.reference_minutes:
                    break
            cs.configure(spp=CYCLES_PASS_SPP, seed=2_000_000 + passes, light_tree=True)
            x, times = cs.render(clock, tmp)
            sync.append(times["sync_s"])
            total, total2, passes = total + x, total2 + x * x, passes + 1
        seconds += time.perf_counter() - start
        np.savez(out, total=total, total2=total2, passes=passes, pass_spp=CYCLES_PASS_SPP, seconds=seconds)
    print(json.dumps({"cycles_reference": args.scene, "spp": passes * CYCLES_PASS_SPP, "seconds": round(seconds, 1),
                      "floor": floor, "pilot_relmse": error, "pilot_spp": args.spp,
                      "sync_s": None if not sync else round(float(np.median(sync)), 2),
                      "config": f"cycles tree 1+1, {CYCLES_PASS_SPP}-spp passes", **info}), flush=True)  # fmt: skip


def cycles_runs(args) -> None:
    """Under bpy: every Cycles configuration (:data:`CYCLES_CONFIGS`) at ``--spp``, ``--seeds`` images each (seeds 1,
    2, ... after an untimed render with seed 10,000), relMSE against the scene's Cycles reference (and, for the
    record, against Mitsuba's); seconds = the median path-tracing time (Cycles' first "Sample" status line to
    "Finished"), ``sync_s`` the median scene sync before it (BVH, light tree, importance map: every render, as a final
    render); one JSON line per configuration."""
    cs, clock, info = _cycles_setup(args)
    cache = Path(args.cache)
    ref = load_reference(cycles_reference_file(cache, args.scene, args.resolution))
    mitsuba_file = reference_file(cache, args.scene, args.resolution)
    mitsuba = load_reference(mitsuba_file)["mean"] if mitsuba_file.exists() else None
    pixels = args.resolution[0] * args.resolution[1]
    with tempfile.TemporaryDirectory() as tmp:
        for name, tree in CYCLES_CONFIGS:
            cs.configure(spp=args.spp, seed=10_000, light_tree=tree)
            cs.render(clock, tmp)  # kernels loaded, caches warm
            errors, against_mitsuba, times = [], [], []
            for s in range(args.seeds):
                cs.configure(spp=args.spp, seed=s + 1, light_tree=tree)
                x, t = cs.render(clock, tmp)
                errors.append(relmse(x, ref["mean"]))
                if mitsuba is not None:
                    against_mitsuba.append(relmse(x, mitsuba))
                times.append(t)
            e = float(np.mean(errors))
            trace = float(np.median([t["trace_s"] if t["trace_s"] is not None else t["wall_s"] for t in times]))
            cpu = sum(t["cpu_s"] for t in times) / sum(t["wall_s"] for t in times)
            row = {"renderer": "cycles", "scene": args.scene, "spp": args.spp, "config": f"cycles {name} 1+1",
                   "relmse": e, "seconds": trace, "efficiency": 1.0 / (e * trace),
                   "sync_s": round(float(np.median([t["sync_s"] or 0.0 for t in times])), 3),
                   "wall_s": round(float(np.median([t["wall_s"] for t in times])), 3), "cpu_util": round(cpu, 2),
                   "samples_per_s": pixels * args.spp / trace, "reference_floor": ref["floor"],
                   "floor_ratio": ref["floor"] / e if e > 0 else None,
                   "relmse_mitsuba_ref": float(np.mean(against_mitsuba)) if against_mitsuba else None,
                   **info}  # fmt: skip
            print(json.dumps(row), flush=True)


def cycles_table(rows: list[dict]) -> str:
    """The Cycles configurations' rows (Markdown): seconds of path tracing and of scene sync per render, relMSE
    against Cycles' reference and against Mitsuba's, efficiency, the reference's floor / the error, CPU use."""
    lines = [
        "| scene | spp | Cycles configuration | trace s | sync s | relMSE (Cycles ref) | efficiency "
        "| relMSE (Mitsuba ref) | Cycles ref floor / error | M samples/s | cpu util |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted((r for r in rows if r["renderer"] == "cycles"), key=lambda r: (r["scene"], r["spp"], r["config"])):
        lines.append(
            f"| {r['scene']} | {r['spp']} | {r['config']} | {r['seconds']:.2f} | {_f(r.get('sync_s'), '.2f')} | "
            f"{r['relmse']:.3g} | {r['efficiency']:.3g} | {_f(r.get('relmse_mitsuba_ref'), '.3g')} | "
            f"{_f(r.get('floor_ratio'), '.3f')} | {_f(r.get('samples_per_s') and r['samples_per_s'] / 1e6, '.2f')} | "
            f"{_f(r.get('cpu_util'), '.2f')} |"
        )
    return "\n".join(lines)


def agreement_table(references: dict) -> str:
    """Cycles' reference against Mitsuba's per scene (Markdown): the translation's check."""
    lines = [
        "| scene | Cycles ref spp | floor | relMSE Cycles vs Mitsuba ref (noise alone) | pooled z image "
        "| blocks max z, share > 4 | mean ratio RGB | Lambertian pixels: relMSE (noise), z, mean ratio |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for scene, ref in sorted(references.items()):
        c, a = ref.get("cycles"), ref.get("cycles_agreement")
        if not c or not a:
            continue
        lam = a.get("lambertian")
        lam_text = "-" if lam is None else (
            f"{lam['relmse']:.3g} ({lam['noise_relmse']:.3g}), {lam['z_image']:+.1f}, "
            f"{', '.join(f'{x:.4f}' for x in lam['mean_ratio'])}")  # fmt: skip
        lines.append(
            f"| {scene} | {c.get('spp', '-')} | {_f(c.get('floor'), '.2g')} | "
            f"{a['relmse']:.3g} ({a['noise_relmse']:.3g}) | {a['z_image']:+.1f} | "
            f"{a['z_blocks_max']:.1f}, {a['z_blocks_over4']:.3f} | "
            f"{', '.join(f'{x:.4f}' for x in a['mean_ratio'])} | {lam_text} |"
        )
    return "\n".join(lines)


# -------------------------------------------------------------------------------------------------------- main


MITSUBA_WORKERS = ("mitsuba", "reference")  # the workers that render with Mitsuba (the pilot is lightprobe's)


def _run(args, worker: str, scene: str, *extra: str, python: str | None = None, echo: bool = True) -> list[dict]:
    cmd = [python or sys.executable, __file__, "--worker", worker, "--scene", scene, "--seeds", str(args.seeds),
           "--resolution", *map(str, args.resolution), "--cache", str(args.cache),
           *[x for o in args.lightprobe_option for x in ("--lightprobe-option", o)], *extra]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    rows = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    if out.returncode != 0:
        remedy = _mitsuba_references().llvm_crash(out.stderr) if worker in MITSUBA_WORKERS else None
        if remedy is not None:  # every later Mitsuba render would abort the same way: stop the run, in one line
            raise SystemExit(f"suite.py: {worker} worker on {scene}: {remedy}")
        raise RuntimeError(f"{worker} worker on {scene} failed:\n{out.stderr[-3000:]}")
    for row in rows if echo else ():
        print(json.dumps(row), flush=True)
    return rows


def main() -> int:
    sys.path.insert(0, str(ROOT / "src"))
    try:
        from lightprobe.reference_scenes import SUITE, unavailable
    except ImportError:  # the Cycles workers run under bpy's Python, which need not have lightprobe's dependencies
        if "--worker" not in sys.argv:
            raise
        SUITE, unavailable = None, None

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=list(SUITE or ()), choices=SUITE)
    parser.add_argument("--spp", type=int, nargs="*", default=[16, 64, 256])
    parser.add_argument("--seeds", type=int, default=2, help="images per configuration and spp [2]")
    parser.add_argument("--resolution", type=int, nargs=2, default=[320, 240])
    parser.add_argument("--cache", default=str(Path.home() / ".cache" / "lightprobe-suite"))
    parser.add_argument("--lightprobe-option", action="append", default=[], metavar="KEY=VALUE",
                        help="a RenderSettings field for lightprobe's renders (repeatable)")  # fmt: skip
    parser.add_argument("--reference-minutes", type=float, default=8.0,
                        help="the most a reference may run in one call, per scene [8]")  # fmt: skip
    parser.add_argument("--write-docs", action="store_true", help="write the table into docs/performance.md")
    parser.add_argument("--quick", action="store_true", help="16 spp, one seed, references of at most a minute")
    parser.add_argument("--spread", action="store_true",
                        help="no references: relMSE from the seeds' spread (--seeds >= 2); no Cycles")  # fmt: skip
    parser.add_argument("--json", help="also write every row to this file")
    parser.add_argument("--table-from", metavar="LOG", nargs="+",
                        help="no renders: the table (and --write-docs) from a run's printed output; with several "
                             "logs, each renderer's rows of a scene from the last log that has them")  # fmt: skip
    parser.add_argument("--lightprobe-only", action="store_true",
                        help="lightprobe's rows alone (references made or extended as usual); the peers' "
                             "rows then from an earlier run's log: --table-from OLD.log NEW.log")  # fmt: skip
    parser.add_argument("--cycles-python", metavar="PYTHON",
                        help="the Python with bpy for the Cycles peer [$LIGHTPROBE_CYCLES_PYTHON, else "
                             f"{CYCLES_PYTHON} if it exists]; 'none': no Cycles")  # fmt: skip
    parser.add_argument("--worker", choices=["mitsuba", "reference", "lightprobe", "pilot", "occlusion", "cycles",
                                             "cycles-reference"],
                        help=argparse.SUPPRESS)  # fmt: skip
    parser.add_argument("--scene", help=argparse.SUPPRESS)
    parser.add_argument("--pilot", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.quick:
        args.spp, args.seeds, args.reference_minutes = [16], 1, 1.0
    if args.spread and args.seeds < 2:
        parser.error("--spread measures each configuration's variance between its seeds: --seeds must be >= 2")
    if args.worker:
        os.environ.setdefault("LIGHTPROBE_SUITE_CACHE", args.cache)
        args.spp = args.spp[0]
        {"mitsuba": mitsuba_runs, "reference": mitsuba_reference, "lightprobe": lightprobe_runs,
         "pilot": lightprobe_pilot, "occlusion": occlusion, "cycles": cycles_runs,
         "cycles-reference": cycles_reference}[args.worker](args)  # fmt: skip
        return 0

    if args.table_from:
        return _table_from(args)
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    os.environ["LIGHTPROBE_SUITE_CACHE"] = str(cache)  # the workers' (the peer kit's assets)
    started = time.perf_counter()
    bpy_python, no_cycles = cycles_python("none" if args.lightprobe_only or args.spread else args.cycles_python)
    if args.lightprobe_only:
        no_cycles = "turned off (--lightprobe-only)"
    if args.spread:
        no_cycles = "left out by --spread (its conductors converge to another image)"
    header = {"cores": os.cpu_count(), "spp": args.spp, "seeds": args.seeds, "resolution": args.resolution,
              "lightprobe_options": parse_options(args.lightprobe_option), "commit": _commit(),
              "date": datetime.date.today().isoformat(), "cycles": no_cycles or "yes",
              "spread": args.spread}  # fmt: skip
    print(json.dumps(header), flush=True)
    rows, references, notes = [], {}, {}
    if no_cycles:
        print(f"cycles: skipped: {no_cycles}", flush=True)
    for scene in args.scenes:
        reason = unavailable(scene)
        if reason is not None:
            print(f"{scene}: skipped: {reason}", flush=True)
            notes[scene] = f"skipped: {reason}"
            continue
        scene_start = time.perf_counter()
        if args.spread:
            try:
                rows += _spread_scene(args, scene, references)
            except RuntimeError as exc:
                print(f"{scene}: failed: {exc}", flush=True)
                notes[scene] = "failed (see the run's output)"
            references.setdefault(scene, {})["run_minutes"] = (time.perf_counter() - scene_start) / 60
            continue
        try:
            top = str(max(args.spp))
            pilot = str(cache / f"{scene}_pilot_{top}spp.npy")
            _run(args, "pilot", scene, "--spp", top, "--pilot", pilot)
            made = _run(args, "reference", scene, "--spp", top, "--pilot", pilot,
                        "--reference-minutes", str(args.reference_minutes))[0]  # fmt: skip
            references[scene] = {**load_reference(reference_file(cache, scene, args.resolution)), **made}
            del references[scene]["mean"], references[scene]["variance"]
            shown = _run(args, "occlusion", scene)[0]
            if shown.get("unoccluded") is not None:
                references[scene]["unoccluded"] = shown["unoccluded"]
            cycles = bpy_python and _cycles_reference(args, scene, top, bpy_python, references, notes)
            for spp in args.spp:
                if not args.lightprobe_only:
                    rows += _run(args, "mitsuba", scene, "--spp", str(spp))
                rows += _run(args, "lightprobe", scene, "--spp", str(spp))
                if cycles:
                    rows += _run(args, "cycles", scene, "--spp", str(spp), python=bpy_python)
        except RuntimeError as exc:
            print(f"{scene}: failed: {exc}", flush=True)
            notes[scene] = "failed (see the run's output)"
        references.setdefault(scene, {})["run_minutes"] = (time.perf_counter() - scene_start) / 60
    minutes = (time.perf_counter() - started) / 60
    _report(args, header, rows, references, notes, minutes)
    return 0


def _spread_scene(args, scene: str, references: dict) -> list[dict]:
    """``--spread``: every spp's Mitsuba and lightprobe rows of ``scene``, measured by :func:`spread_metrics` and
    printed."""
    shown = _run(args, "occlusion", scene)[0]
    references[scene] = {"config": "none (relMSE from the spread between seeds)", "spread": True}
    if shown.get("unoccluded") is not None:
        references[scene]["unoccluded"] = shown["unoccluded"]
    raw = []
    for spp in args.spp:
        if not args.lightprobe_only:
            raw += _run(args, "mitsuba", scene, "--spp", str(spp), "--spread", echo=False)
        raw += _run(args, "lightprobe", scene, "--spp", str(spp), "--spread", echo=False)
    rows = spread_metrics(raw)
    for row in rows:
        print(json.dumps(row), flush=True)
    return rows


def _cycles_reference(args, scene: str, top: str, python: str, references: dict, notes: dict) -> bool:
    """Export the scene for Cycles, make (or extend) its Cycles reference and compare it with Mitsuba's; False (with
    a printed reason) where the scene is not translated."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cycles_scene

    cache = Path(args.cache)
    try:
        export_cycles_scene(cache, scene, args.resolution)
    except cycles_scene.NotTranslated as exc:
        print(f"{scene}: cycles skipped: not translated: {exc}", flush=True)
        notes[scene] = f"Cycles skipped: not translated: {exc}"
        return False
    made = _run(args, "cycles-reference", scene, "--spp", top, "--reference-minutes", str(args.reference_minutes),
                python=python)[0]  # fmt: skip
    references[scene]["cycles"] = made
    agreement = reference_agreement(load_reference(cycles_reference_file(cache, scene, args.resolution)),
                                    load_reference(reference_file(cache, scene, args.resolution)),
                                    conductor_mask(scene, args.resolution))  # fmt: skip
    references[scene]["cycles_agreement"] = agreement
    print(json.dumps({"agreement": scene, **agreement}), flush=True)
    return True


def _commit() -> str:
    """The checkout's short commit, marked when files differ from it (what a table says it measured)."""

    def git(*words):
        return subprocess.run(["git", *words], capture_output=True, text=True, cwd=ROOT).stdout.strip()

    head = git("rev-parse", "--short", "HEAD")
    if not head:
        return "unknown (not a git checkout)"
    return head + (" with uncommitted changes" if git("status", "--porcelain", "--untracked-files=no") else "")


def _table_from(args) -> int:
    """The table of earlier runs from their printed output (one JSON object per line; a run cut short gives the
    rows it finished).  With several logs, a renderer's rows of a scene at an spp come from the last log that has
    that renderer's rows of it at that spp (a run of some scenes after a change replaces lightprobe's and the peers'
    rows there and keeps another peer's; a run at 256 spp alone keeps the 16- and 64-spp rows), references merge,
    and the table says which commit measured what; the logs must share resolution, seeds and lightprobe options."""
    from lightprobe.reference_scenes import SUITE

    rows, references, notes, header, measured = [], {}, {}, None, {}
    for log in args.table_from:
        got, refs, this = [], {}, None
        for line in Path(log).read_text().splitlines():
            if line.endswith(": skipped") or ": skipped: " in line or ": failed: " in line:
                scene, _, note = line.partition(": ")
                if scene in SUITE:  # not a peer's line ("cycles: skipped: ..."), whose rows may come from another log
                    notes[scene] = note
            if not line.startswith("{"):
                continue
            item = json.loads(line)
            if "cores" in item:
                this = item
            elif "renderer" in item:
                got.append(item)
            elif "reference" in item:
                refs.setdefault(item["reference"], {}).update(item)
            elif "cycles_reference" in item:
                refs.setdefault(item["cycles_reference"], {})["cycles"] = item
            elif "agreement" in item:
                refs.setdefault(item["agreement"], {})["cycles_agreement"] = item
            elif "occlusion" in item and item.get("unoccluded") is not None:
                refs.setdefault(item["occlusion"], {})["unoccluded"] = item["unoccluded"]
        if this is None:
            raise SystemExit(f"{log}: no run header")
        if header is not None:
            for key in ("resolution", "seeds", "lightprobe_options"):
                if this[key] != header[key]:
                    raise SystemExit(f"{log}: its {key} {this[key]} differs from the first log's {header[key]}")
            this = {**this, "spp": sorted(set(header["spp"]) | set(this["spp"]))}
        header = this
        measures = {(row["scene"], row["renderer"], row["spp"]) for row in got}
        rows = [row for row in rows if (row["scene"], row["renderer"], row["spp"]) not in measures] + got
        for scene, ref in refs.items():
            references.setdefault(scene, {}).update(ref)
        for key in measures:
            measured[key] = (this.get("commit") or "unknown", this.get("date") or "an unknown date")
    args.resolution, args.seeds, args.spp = header["resolution"], header["seeds"], header["spp"]
    args.lightprobe_option = [f"{k}={json.dumps(v)}" for k, v in header["lightprobe_options"].items()]
    if len(set(measured.values())) > 1:
        runs_of: dict = {}  # (scene, renderer) -> {run: [spp, ...]}
        for (scene, renderer, spp), run in sorted(measured.items()):
            runs_of.setdefault((scene, renderer), {}).setdefault(run, []).append(spp)
        by_run: dict = {}
        for (scene, renderer), runs in runs_of.items():
            for run, spps in runs.items():  # the spp named only where a renderer's rows of a scene span runs
                at = f" {'/'.join(map(str, spps))} spp" if len(runs) > 1 else ""
                by_run.setdefault(run, []).append(f"{scene} {renderer}{at}")
        header = {**header, "commit": "; ".join(f"{c} ({d}: {', '.join(names)})" for (c, d), names in by_run.items()),
                  "date": " / ".join(sorted({d for _, d in by_run}))}  # fmt: skip
    _report(args, header, rows, references, notes, None)
    return 0


def _report(args, header: dict, rows: list[dict], references: dict, notes: dict, minutes: float | None) -> None:
    """Print the tables (and write them into docs/performance.md with ``--write-docs``)."""
    summary = summarise(rows, references)
    pixels = args.resolution[0] * args.resolution[1]
    text = table(summary, pixels)
    print(text)
    print()
    print(peer_table(summary))
    print()
    cycles = cycles_table(rows)
    if any(r["renderer"] == "cycles" for r in rows):
        print(cycles)
        print()
    agreement = agreement_table(references)
    if any(ref.get("cycles_agreement") for ref in references.values()):
        print(agreement)
        print()
    for scene, ref in references.items():
        print(f"{scene}: " + json.dumps(ref))
    took = "" if minutes is None else f"; the run took {minutes:.0f} minutes"
    if minutes is not None:
        print(f"suite: {len(references)} scenes in {minutes:.1f} minutes")
    if args.json:
        Path(args.json).write_text(json.dumps({"header": header, "rows": rows, "references": references,
                                               "notes": notes}, indent=1))  # fmt: skip
    if args.write_docs:
        # the run's own commit and date (a table written later from its log says when it was measured, not now)
        commit = header.get("commit") or "unknown (a log without one)"
        day = header.get("date") or "on a date the log does not give"
        lines = [
            f"Measured {day} on {header['cores']} cores (a shared machine: timings are "
            f"indicative), commit {commit}, {args.resolution[0]} x {args.resolution[1]}, "
            f"{args.seeds} seed(s), spp {', '.join(map(str, args.spp))}; lightprobe options: "
            f"{header['lightprobe_options'] or 'defaults'}{took}.",
            "",
            text,
            "",
        ]
        spread = header.get("spread")
        if spread:
            lines[0] += (" No references (`--spread`): each relMSE is the variance between the seeds' images over "
                         "(m^2 + 0.01), m the mean of all of the scene's renders; the pooled z is lightprobe's "
                         "seeds' mean against the mean of all of Mitsuba's renders.")  # fmt: skip
        else:
            lines += [
                "References (Mitsuba `direct`; floor = mean(var_ref / (ref^2 + 0.01))):",
                "",
                "| scene | reference | spp | seconds | floor | Mitsuba load s | unoccluded light power |",
                "|---|---|---|---|---|---|---|",
            ]
        for scene, ref in references.items() if not spread else ():
            lines.append(f"| {scene} | {ref.get('config', '-')} | {ref.get('spp', '-')} | "
                         f"{_f(ref.get('seconds'), '.0f')} | {_f(ref.get('floor'), '.2g')} | "
                         f"{_f(ref.get('load_s'), '.2f')} | {_f(ref.get('unoccluded'), '.3f')} |")  # fmt: skip
        for scene, note in notes.items():
            lines.append(f"\n{scene}: {note}")
        lines += ["", "Efficiency of every configuration:", "", peer_table(summary)]
        if any(r["renderer"] == "cycles" for r in rows):
            lines += ["", "Blender Cycles (bpy; seconds = path tracing, sync = the scene's sync before it in every "
                      "render; relMSE against Cycles' own reference):", "", cycles]  # fmt: skip
        if any(ref.get("cycles_agreement") for ref in references.values()):
            lines += ["", "Cycles' reference against Mitsuba's (the translation's check; Lambertian pixels: where "
                      "no rough conductor is seen):", "", agreement]  # fmt: skip
        write_docs("\n".join(lines))
        print("wrote docs/performance.md", flush=True)


if __name__ == "__main__":
    sys.exit(main())
