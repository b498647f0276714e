#!/usr/bin/env python3
"""Micro-benchmark: the environment's bilinear RGB lookup, scalar Numba against the renderer's 8 lanes of LLVM IR.

    python benchmarks/simd_lookup.py            # one JSON line per case (random / coherent coordinates)

Numba does not vectorise a loop that reads a table (docs/decisions.md 35); ``emitters/envmap_lanes.radiance_block``
is an ``@intrinsic`` that builds the whole lookup for 8 slots as vector IR (decisions.md 41-43).  It computes what
``lightprobe.emitters.envmap.env_lookup`` does (same formula; where LLVM fuses a multiply-add in one and not the
other they differ by an ulp).  Each line gives core-nanoseconds per lookup (best of 5 runs of 8 M lookups on every
core) both ways, and, when Mitsuba 3 imports, its ``Texture2f.eval`` on the same image (float32 lanes) for scale.
Measured on the peer map, three runs: random coordinates 21.7-24.0 against 19.8-24.3 scalar, coherent 8.1-8.6
against 13.7-14.0 (Mitsuba 4.9-5.3 and 2.4; decisions.md 43).  The first version read texels with
``llvm.masked.gather`` and took 9.3-9.4 against 19.7-20.1 on random coordinates, 6.7-6.8 against 12.8-13.2 on
coherent ones (decisions.md 41); in the render the two read the same speed.  Uses the peer kit's map when it is
found (``LIGHTPROBE_PEERS``), else a procedural 1024 x 512 sky.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from numba import njit, prange

from lightprobe.integrators.stages.environment_lanes import LANES, radiance_block


@njit(parallel=True)
def lanes(out, image, uv, state):
    for block in prange((state.shape[0] + LANES - 1) // LANES):
        radiance_block(out, image, uv, state, block * LANES)


def _scalar_kernel():
    from lightprobe._numba import FASTMATH
    from lightprobe.emitters.envmap import env_lookup

    @njit(parallel=True, error_model="numpy", fastmath=FASTMATH)
    def scalar(k, uv, out):
        for r in prange(uv.shape[0]):
            out[r, 0], out[r, 1], out[r, 2] = env_lookup(k, uv[r, 0], uv[r, 1])

    return scalar


def _best_core_ns(kernel, args: tuple, n: int, cores: int) -> float:
    times = []
    for _ in range(5):
        start = time.perf_counter()
        kernel(*args)
        times.append(time.perf_counter() - start)
    return min(times) / n * 1e9 * cores


def _environment():
    from lightprobe.emitters.envmap import EnvironmentMap
    from lightprobe.peer import find_peers, peer_assets

    if find_peers() is not None:
        return EnvironmentMap.from_array(peer_assets()[0], source="peer env.exr"), "peer env.exr"
    from lightprobe.emitters.procedural import sky_with_sun

    return EnvironmentMap.from_array(sky_with_sun(width=1024, height=512), source="sky"), "procedural sky 1024x512"


def _mitsuba_eval(image: np.ndarray, u: np.ndarray, v: np.ndarray, n: int, cores: int) -> float | None:
    try:
        import drjit as dr
        import mitsuba as mi

        mi.set_variant("llvm_ad_rgb")
    except Exception:
        return None
    texture = mi.Texture2f(mi.TensorXf(np.ascontiguousarray(image)))
    uv = mi.Point2f(u.astype(np.float32), v.astype(np.float32))
    dr.eval(uv)

    def run():
        dr.eval(texture.eval(uv))
        dr.sync_thread()

    run()  # compiles
    return _best_core_ns(run, (), n, cores)


def main() -> int:
    import numba

    env, source = _environment()
    k = env.kernel
    scalar = _scalar_kernel()
    cores = numba.get_num_threads()
    n = 1 << 23
    rng = np.random.default_rng(1)
    cases = {
        "random": (rng.random(n), rng.random(n)),
        "coherent": (0.3 + 1e-3 * rng.random(n), 0.3 + 1e-3 * rng.random(n)),
    }
    live = np.ones(n, np.int8)
    for case, (u, v) in cases.items():
        uv = np.ascontiguousarray(np.stack([u, v], axis=1))
        a, b = np.empty((n, 3)), np.empty((n, 3))
        lanes(a, k.image, uv, live)
        scalar(k, uv, b)
        difference = float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))
        if difference > 1e-15:
            sys.exit(f"the 8-lane lookup differs from env_lookup by {difference:.3g} (relative)")
        line = {
            "map": source,
            "coordinates": case,
            "lookups": n,
            "scalar_core_ns": round(_best_core_ns(scalar, (k, uv, b), n, cores), 2),
            "lanes8_core_ns": round(_best_core_ns(lanes, (a, k.image, uv, live), n, cores), 2),
            "largest_relative_difference": difference,
            "mitsuba_texture2f_core_ns": _mitsuba_eval(np.asarray(k.image), u, v, n, cores),
            "cores": cores,
        }
        if line["mitsuba_texture2f_core_ns"] is not None:
            line["mitsuba_texture2f_core_ns"] = round(line["mitsuba_texture2f_core_ns"], 2)
        print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
