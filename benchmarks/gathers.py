#!/usr/bin/env python3
"""Micro-benchmark: random table reads as scalar loads against 8-wide gathers (``llvm.masked.gather``).

    python benchmarks/gathers.py                  # tables of 16 KB, 1 MB and 32 MB; one JSON line each

Numba's auto-vectoriser emits no gathers for table reads (docs/decisions.md 35), so this emits them itself from an
``@intrinsic``: 8 indices loaded as a vector, 8 addresses formed as integers (llvmlite's IR builder has no vector
GEP), one ``llvm.masked.gather.v8f32.v8p0``, one vector store.  Each line gives the wall nanoseconds per load on
every core (best of 5 runs of 8 M random loads) both ways.  Measured (decisions.md 37): 2.94 against 3.00 ns from
32 MB, the size of a 2K environment map's channels; gathers gain only where the table is cache-resident.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def _gather8(typingctx, out, table, index, start):
    """out[start : start + 8] = table[index[start : start + 8]] (float32 table and out, int32 index)."""

    def codegen(context, builder, signature, args):
        out_v, table_v, index_v, start_v = args
        out_a = context.make_array(signature.args[0])(context, builder, out_v)
        table_a = context.make_array(signature.args[1])(context, builder, table_v)
        index_a = context.make_array(signature.args[2])(context, builder, index_v)
        f32, i32, i64 = ir.FloatType(), ir.IntType(32), ir.IntType(64)
        v8i32, v8i64, v8f32 = ir.VectorType(i32, 8), ir.VectorType(i64, 8), ir.VectorType(f32, 8)
        indices = builder.load(builder.bitcast(builder.gep(index_a.data, [start_v]), v8i32.as_pointer()), align=4)
        base = builder.insert_element(ir.Constant(v8i64, None), builder.ptrtoint(table_a.data, i64), i32(0))
        base = builder.shuffle_vector(base, ir.Constant(v8i64, None), ir.Constant(v8i32, [0] * 8))
        offsets = builder.mul(builder.sext(indices, v8i64), ir.Constant(v8i64, [4] * 8))
        pointers = builder.inttoptr(builder.add(base, offsets), ir.VectorType(f32.as_pointer(), 8))
        mask = ir.VectorType(ir.IntType(1), 8)
        gather = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(v8f32, [pointers.type, i32, mask, v8f32]), "llvm.masked.gather.v8f32.v8p0"
        )
        values = builder.call(gather, [pointers, i32(4), ir.Constant(mask, [1] * 8), ir.Constant(v8f32, None)])
        builder.store(values, builder.bitcast(builder.gep(out_a.data, [start_v]), v8f32.as_pointer()), align=4)
        return context.get_dummy_value()

    return types.void(out, table, index, start), codegen


@njit(parallel=True)
def gathered(out, table, index):
    for block in prange(index.shape[0] // 8):
        _gather8(out, table, index, block * 8)


@njit(parallel=True)
def scalar(out, table, index):
    for i in prange(index.shape[0]):
        out[i] = table[index[i]]


def _best_ns(kernel, args, n: int) -> float:
    times = []
    for _ in range(5):
        start = time.perf_counter()
        kernel(*args)
        times.append(time.perf_counter() - start)
    return min(times) / n * 1e9


def main() -> int:
    rng = np.random.default_rng(0)
    n = 1 << 23
    for floats in (1 << 12, 1 << 18, 1 << 23):
        table = rng.random(floats).astype(np.float32)
        index = rng.integers(0, floats, n).astype(np.int32)
        a, b = np.zeros(n, np.float32), np.zeros(n, np.float32)
        gathered(a, table, index)  # compile and check
        scalar(b, table, index)
        if not np.array_equal(a, b):
            sys.exit("the gathers read other values than the scalar loads")
        line = {
            "table_bytes": 4 * floats,
            "loads": n,
            "scalar_ns_per_load": round(_best_ns(scalar, (b, table, index), n), 3),
            "gather_ns_per_load": round(_best_ns(gathered, (a, table, index), n), 3),
            "cores": os.cpu_count(),
        }
        print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
