#!/usr/bin/env python3
"""Micro-benchmark: the environment's bilinear RGB lookup, scalar Numba against 8 lanes of hand-written LLVM IR.

    python benchmarks/simd_lookup.py            # one JSON line per case (random / coherent coordinates)

Numba does not vectorise a loop that reads a table (docs/decisions.md 35), so the 8-lane lookup is an ``@intrinsic``
that builds the whole lookup as vector IR: coordinates to texels (``llvm.floor``, compares and selects for the
wrap in u and the clamp in v), 12 ``llvm.masked.gather`` of the float32 texels, the bilinear weights in float64.
It computes what ``lightprobe.emitters.envmap.env_lookup`` does (same formula; the scalar kernel may contract a
multiply-add into an FMA, so the two differ by at most an ulp).  Each line gives core-nanoseconds per lookup
(best of 5 runs of 8 M lookups on every core) both ways, and, when Mitsuba 3 imports, its ``Texture2f.eval`` on the
same image (float32 lanes) for scale.  Measured on the peer map (decisions.md 41): random coordinates 9.3-9.4
against 19.7-20.1 scalar (Mitsuba 4.8-5.1), coherent 6.7-6.8 against 12.8-13.2 (Mitsuba 2.4).  Uses the peer kit's
map when it is found (``LIGHTPROBE_PEERS``), else a procedural 1024 x 512 sky.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic

LANES = 8


@intrinsic
def _lookup8(typingctx, out, image, u, v, start):
    """out[c, start : start + 8] = bilinear lat-long lookup of ``image`` (H, W, 3) float32 at (u, v)[start ...]."""

    def codegen(context, builder, signature, args):
        out_v, image_v, u_v, v_v, start_v = args
        out_a = context.make_array(signature.args[0])(context, builder, out_v)
        image_a = context.make_array(signature.args[1])(context, builder, image_v)
        u_a = context.make_array(signature.args[2])(context, builder, u_v)
        v_a = context.make_array(signature.args[3])(context, builder, v_v)
        f32, f64, i32, i64 = ir.FloatType(), ir.DoubleType(), ir.IntType(32), ir.IntType(64)
        vf64, vi64, vf32 = ir.VectorType(f64, LANES), ir.VectorType(i64, LANES), ir.VectorType(f32, LANES)
        mask_t = ir.VectorType(ir.IntType(1), LANES)

        def constant(t, x):
            return ir.Constant(t, [x] * LANES)

        def splat(value, t):
            lane0 = builder.insert_element(ir.Constant(t, None), value, i32(0))
            return builder.shuffle_vector(lane0, ir.Constant(t, None), ir.Constant(ir.VectorType(i32, LANES), [0] * 8))

        def function(name, ret, *params):
            return cgutils.get_or_insert_function(builder.module, ir.FunctionType(ret, list(params)), name)

        h, w, _ = cgutils.unpack_tuple(builder, image_a.shape, 3)
        wv, hv = splat(w, vi64), splat(h, vi64)
        uu = builder.load(builder.bitcast(builder.gep(u_a.data, [start_v]), vf64.as_pointer()), align=8)
        vv = builder.load(builder.bitcast(builder.gep(v_a.data, [start_v]), vf64.as_pointer()), align=8)
        # columns at u = (i + 0.5) / W, periodic; rows at v = j / (H - 1), clamped (mappings.bilinear_latlong_weights)
        fx = builder.fsub(builder.fmul(uu, builder.sitofp(wv, vf64)), constant(vf64, 0.5))
        x0f = builder.call(function("llvm.floor.v8f64", vf64, vf64), [fx])
        tx = builder.fsub(fx, x0f)
        x0 = builder.fptosi(x0f, vi64)
        x0 = builder.select(builder.icmp_signed("<", x0, constant(vi64, 0)), builder.add(x0, wv), x0)
        x0 = builder.select(builder.icmp_signed(">=", x0, wv), builder.sub(x0, wv), x0)
        x1 = builder.add(x0, constant(vi64, 1))
        x1 = builder.select(builder.icmp_signed("<", x1, wv), x1, constant(vi64, 0))
        clamped = builder.call(function("llvm.maxnum.v8f64", vf64, vf64, vf64), [vv, constant(vf64, 0.0)])
        clamped = builder.call(function("llvm.minnum.v8f64", vf64, vf64, vf64), [clamped, constant(vf64, 1.0)])
        fy = builder.fmul(clamped, builder.sitofp(builder.sub(hv, constant(vi64, 1)), vf64))
        last = builder.sub(hv, constant(vi64, 2))
        y0 = builder.fptosi(fy, vi64)
        y0 = builder.select(builder.icmp_signed("<", y0, last), y0, last)
        ty = builder.fsub(fy, builder.sitofp(y0, vf64))
        y1 = builder.add(y0, constant(vi64, 1))
        base = splat(builder.ptrtoint(image_a.data, i64), vi64)
        gather = function(
            "llvm.masked.gather.v8f32.v8p0", vf32, ir.VectorType(f32.as_pointer(), LANES), i32, mask_t, vf32
        )
        corners = [
            builder.mul(builder.add(builder.mul(y, wv), x), constant(vi64, 12)) for y in (y0, y1) for x in (x0, x1)
        ]
        one_tx, one_ty = builder.fsub(constant(vf64, 1.0), tx), builder.fsub(constant(vf64, 1.0), ty)
        n = cgutils.unpack_tuple(builder, out_a.shape, 2)[1]
        for c in range(3):
            texels = []
            for offset in corners:
                address = builder.add(base, builder.add(offset, constant(vi64, 4 * c)))
                pointers = builder.inttoptr(address, ir.VectorType(f32.as_pointer(), LANES))
                loaded = builder.call(gather, [pointers, i32(4), constant(mask_t, 1), ir.Constant(vf32, None)])
                texels.append(builder.fpext(loaded, vf64))
            top = builder.fadd(builder.fmul(one_tx, texels[0]), builder.fmul(tx, texels[1]))
            bottom = builder.fadd(builder.fmul(one_tx, texels[2]), builder.fmul(tx, texels[3]))
            value = builder.fadd(builder.fmul(one_ty, top), builder.fmul(ty, bottom))
            row = builder.add(builder.mul(i64(c), n), start_v)
            builder.store(value, builder.bitcast(builder.gep(out_a.data, [row]), vf64.as_pointer()), align=8)
        return context.get_dummy_value()

    return types.void(out, image, u, v, start), codegen


@njit(parallel=True)
def lanes(out, image, u, v):
    for block in prange(u.shape[0] // LANES):
        _lookup8(out, image, u, v, np.int64(block * LANES))


def _scalar_kernel():
    from lightprobe._numba import FASTMATH
    from lightprobe.emitters.envmap import env_lookup

    @njit(parallel=True, error_model="numpy", fastmath=FASTMATH)
    def scalar(k, u, v, out):
        for r in prange(u.shape[0]):
            out[0, r], out[1, r], out[2, r] = env_lookup(k, u[r], v[r])

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
    for case, (u, v) in cases.items():
        a, b = np.empty((3, n)), np.empty((3, n))
        lanes(a, k.image, u, v)
        scalar(k, u, v, b)
        difference = float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))
        if difference > 1e-15:
            sys.exit(f"the 8-lane lookup differs from env_lookup by {difference:.3g} (relative)")
        line = {
            "map": source,
            "coordinates": case,
            "lookups": n,
            "scalar_core_ns": round(_best_core_ns(scalar, (k, u, v, b), n, cores), 2),
            "lanes8_core_ns": round(_best_core_ns(lanes, (a, k.image, u, v), n, cores), 2),
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
