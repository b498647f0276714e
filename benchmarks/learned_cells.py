#!/usr/bin/env python3
"""The learned light selection's cells (emitters/selection_learning.py, decision 114): the k-d tree over the pilot's
shading points it uses, against a uniform grid over the same points (issue 59: "a spatial grid or tree over the
scene, or image tiles: measure which"; decision 127).

- ``kd``: today's cells, leaves of a k-d tree split at the median of each node's widest axis, at most
  ``LEAF_RECORDS`` records a leaf (as many cells as the records fill);
- ``grid``: the same number of cells or the next power of two, as a uniform grid: the records' bounding box split at
  the middle of its widest extent, level after level, to a fixed depth (empty cells learn nothing);
- ``grid x4``, ``grid /4``: four times as many cells, and a quarter as many;
- ``tiles``, ``tiles /16`` (``--tiles``): image tiles, as many as ``grid``'s cells and a sixteenth as many: a
  receiver's cell is the tile its projection onto the image falls in (for the camera's shading points, the tile of
  their pixel). Measured by patching the cell lookup (``selection.leaf_of``, inlined into the stages) to project
  first, so each scene's tiles render in a process of their own with an empty kernel cache (``--tiles-only``).

Each configuration renders the suite's scenes where the learning keeps cells (the building, the ceiling, the city:
decision 114) at 320 x 240 with lightprobe's defaults, ``--seeds`` seeds each, interleaved; relMSE from the spread
between seeds over (m^2 + 0.01), m the mean of every render of the scene (decision 124), seconds the median,
efficiency 1 / (relMSE x seconds), and each over ``kd``'s.

    python benchmarks/learned_cells.py [--scenes building ceiling city] [--spp 64] [--seeds 4] [--first-seed 20]
    python benchmarks/learned_cells.py --tiles
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

CONFIGS = {"kd": None, "grid": 1, "grid x4": 4, "grid /4": 0.25}
TILES = {"tiles": 1, "tiles /16": 1 / 16}


def project(cam: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) points -> (N, 3) (pixel column, pixel row, 0) of their projection (``Camera.kernel_array``'s layout)."""
    d = points - cam[0:3]
    zc, xc, yc = d @ cam[3:6], d @ cam[6:9], d @ cam[9:12]
    i = (xc / zc / cam[12] + 1.0) * 0.5 * cam[14]
    j = (1.0 - yc / zc / cam[13]) * 0.5 * cam[15]
    return np.stack([i, j, np.zeros_like(i)], axis=1)


def patch_for_tiles(cam: np.ndarray, factor: float) -> None:
    """Cells become image tiles: the cell lookup projects a point first, and the cells' tree is a uniform grid over
    the records' projections.  Must run before anything compiles (the stages inline the lookup)."""
    from numba import njit

    from lightprobe.emitters import selection, selection_learning

    frozen = np.ascontiguousarray(cam, dtype=np.float64)

    @njit(inline="always")
    def tile_leaf_of(axis, split, nxt, px, py, pz):
        dx, dy, dz = px - frozen[0], py - frozen[1], pz - frozen[2]
        zc = dx * frozen[3] + dy * frozen[4] + dz * frozen[5]
        xc = dx * frozen[6] + dy * frozen[7] + dz * frozen[8]
        yc = dx * frozen[9] + dy * frozen[10] + dz * frozen[11]
        i = (xc / zc / frozen[12] + 1.0) * 0.5 * frozen[14]
        j = (1.0 - yc / zc / frozen[13]) * 0.5 * frozen[15]
        node = 0
        while axis[node] >= 0:
            x = i if axis[node] == 0 else (j if axis[node] == 1 else 0.0)
            node = nxt[node, 0 if x < split[node] else 1]
        return nxt[node, 0]

    def tile_tree(points, leaf):
        return grid_tree(project(frozen, np.asarray(points, np.float64)), factor * points.shape[0] / max(leaf, 1))

    selection.leaf_of = tile_leaf_of
    selection_learning.leaf_of = tile_leaf_of
    selection_learning._kd_tree = tile_tree


def grid_tree(points: np.ndarray, cells: float):
    """A uniform grid of about ``cells`` cells (the next power of two) over ``points``' bounding box, as the k-d
    tree's arrays (axis, split, next): each level splits every node's box at the middle of its widest extent."""
    depth = max(0, math.ceil(math.log2(max(cells, 1.0))))
    lo, hi = points.min(axis=0).astype(np.float64), points.max(axis=0).astype(np.float64)
    axis, split, nxt = [], [], []
    boxes = [(lo, hi, 0)]  # (lo, hi, depth) of node i
    i = 0
    while i < len(boxes):
        b_lo, b_hi, d = boxes[i]
        axis.append(-1)
        split.append(0.0)
        nxt.append([0, 0])
        extent = b_hi - b_lo
        if d < depth and extent.max() > 0.0:
            a = int(np.argmax(extent))
            mid = 0.5 * (b_lo[a] + b_hi[a])
            left_hi, right_lo = b_hi.copy(), b_lo.copy()
            left_hi[a], right_lo[a] = mid, mid
            axis[i], split[i] = a, mid
            nxt[i] = [len(boxes), len(boxes) + 1]
            boxes.append((b_lo, left_hi, d + 1))
            boxes.append((right_lo, b_hi, d + 1))
        i += 1
    axis, split, nxt = np.array(axis, np.int64), np.array(split), np.array(nxt, np.int64)
    leaves = np.flatnonzero(axis < 0)
    nxt[leaves, 0] = np.arange(leaves.size)
    return axis, split, nxt


def _render(scene, spp: int, seed: int, config: str):
    from lightprobe.emitters import selection_learning
    from lightprobe.integrators.settings import RenderSettings
    from lightprobe.integrators.wavefront import render

    factor = CONFIGS[config]
    original = selection_learning._kd_tree
    if factor is not None:

        def tree(points, leaf):
            return grid_tree(points, factor * points.shape[0] / max(leaf, 1))

        selection_learning._kd_tree = tree
    try:
        start = time.perf_counter()
        result = render(scene, RenderSettings(spp=spp, seed=seed))
        return result.image.astype(np.float64), time.perf_counter() - start, result.stats
    finally:
        selection_learning._kd_tree = original


def tiles_only(out: Path, name: str, config: str, spp: int, seeds: range) -> None:
    """``--tiles-only``: scene ``name``'s renders with ``config``'s tiles (a fresh process and kernel cache),
    saved to ``out`` for the parent."""
    from lightprobe import reference_scenes
    from lightprobe.integrators.settings import RenderSettings
    from lightprobe.integrators.wavefront import render

    scene = reference_scenes.build(name, resolution=reference_scenes.SUITE_RESOLUTION)
    patch_for_tiles(scene.camera.kernel_array(), TILES[config])
    render(scene, RenderSettings(spp=spp, seed=99))  # compiles (the learning and the probe run only in long renders)
    seconds = []
    for seed in seeds:
        start = time.perf_counter()
        result = render(scene, RenderSettings(spp=spp, seed=seed))
        seconds.append(time.perf_counter() - start)
        np.save(out / f"{seed}.npy", result.image.astype(np.float64))
    (out / "seconds.json").write_text(json.dumps(seconds))


def _tiles_runs(name: str, config: str, spp: int, seeds: range) -> tuple[list, list]:
    import os
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        out.mkdir()
        env = dict(os.environ, XDG_CACHE_HOME=str(Path(tmp) / "cache"))
        env.pop("NUMBA_CACHE_DIR", None)  # lightprobe set it for this process: the child's cache must be its own
        subprocess.run([sys.executable, __file__, "--tiles-only", str(out), "--tiles-config", config, "--scenes", name,
                        "--spp", str(spp), "--seeds", str(len(seeds)), "--first-seed", str(seeds[0])], env=env,
                       check=True)  # fmt: skip
        images = [np.load(out / f"{seed}.npy") for seed in seeds]
        return images, json.loads((out / "seconds.json").read_text())


def main() -> int:
    from lightprobe import reference_scenes
    from suite import _seed_variance

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="*", default=["building", "ceiling", "city"])
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--first-seed", type=int, default=20)
    parser.add_argument("--tiles", action="store_true", help="image tiles too (a process per scene and tiling)")
    parser.add_argument("--configs", nargs="*", help="only these (kd first: the ratios are over it)")
    parser.add_argument("--tiles-only", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--tiles-config", default="tiles", help=argparse.SUPPRESS)
    args = parser.parse_args()
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    if args.tiles_only is not None:
        tiles_only(args.tiles_only, args.scenes[0], args.tiles_config, args.spp, seeds)
        return 0
    configs = [*CONFIGS, *(TILES if args.tiles else ())]
    if args.configs:
        configs = [c for c in configs if c in args.configs]
    table = []
    for name in args.scenes:
        scene = reference_scenes.build(name, resolution=reference_scenes.SUITE_RESOLUTION)
        in_process = [c for c in configs if c in CONFIGS]
        for config in in_process:
            _render(scene, args.spp, 99, config)  # compiles (the learning and the probe run only in long renders)
        images = {c: [] for c in configs}
        seconds = {c: [] for c in configs}
        for seed in seeds:
            for config in in_process:
                image, s, _ = _render(scene, args.spp, seed, config)
                images[config].append(image)
                seconds[config].append(s)
        for config in configs:
            if config in TILES:
                images[config], seconds[config] = _tiles_runs(name, config, args.spp, seeds)
        mean = sum(sum(v) for v in images.values()) / sum(len(v) for v in images.values())
        rows = {}
        for config in configs:
            relmse = float(np.mean(_seed_variance(images[config]) / (mean * mean + 0.01)))
            s = statistics.median(seconds[config])
            rows[config] = {"scene": name, "config": config, "spp": args.spp, "seeds": args.seeds, "relmse": relmse,
                            "seconds": s, "efficiency": 1.0 / (relmse * s)}  # fmt: skip
        for row in rows.values():
            row["efficiency_over_kd"] = row["efficiency"] / rows["kd"]["efficiency"]
            print(json.dumps(row), flush=True)
            table.append(row)
    print("\n| scene | " + " | ".join(configs) + " |")
    print("|---|" + "---|" * len(configs))
    for name in dict.fromkeys(r["scene"] for r in table):
        mine = {r["config"]: r for r in table if r["scene"] == name}
        cells = [f"{mine[c]['relmse']:.4g} in {mine[c]['seconds']:.2f} s, {mine[c]['efficiency_over_kd']:.2f}x"
                 for c in configs]  # fmt: skip
        print(f"| {name} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
