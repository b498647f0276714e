"""The environment's bilinear radiance lookups eight shading slots at a time, as vector LLVM IR.

Numba compiles the renderer's kernels one slot at a time: its vectoriser gives up on any loop that reads a table
(docs/decisions.md 35), so each lookup's 12 texel reads and its arithmetic run in scalar code.  Written as vector IR
(a Numba ``@intrinsic``) the same lookup takes half the time: 9.4 against 20 core-ns for random coordinates on the
peer map, 6.7 against 13 for coherent ones (decisions.md 41, ``benchmarks/simd_lookup.py``).

:func:`radiance_block` computes what :func:`lightprobe.emitters.envmap.env_lookup` does for a bilinear lat-long
map -- Mitsuba's texel placement, see :func:`lightprobe.emitters.mappings.bilinear_latlong_weights` -- for the
slots ``start .. start + 7`` of a pass: the lanes past the end of the arrays and the lanes of dead slots
(``SLOT_NONE``) neither read nor write anything (masked gathers and scatters).  Every slot of a pass goes through
it, whatever the pass size, so the image does not depend on how slots fall into blocks.  It runs the formula in
float64 without fused multiply-adds; the scalar kernels may fuse some, so the two differ by at most an ulp.

Coordinates outside the lookup's domain (a NaN, or far outside [0, 1]) are clamped before they become texel
indices: a vector lane cannot take the scalar code's slow path, and an index from a NaN would address any memory.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from .._numba import jit_parallel, prange

LANES = 8

_F32, _F64, _I8, _I32, _I64 = ir.FloatType(), ir.DoubleType(), ir.IntType(8), ir.IntType(32), ir.IntType(64)
_VF64, _VI64, _VF32 = ir.VectorType(_F64, LANES), ir.VectorType(_I64, LANES), ir.VectorType(_F32, LANES)
_VI8, _MASK = ir.VectorType(_I8, LANES), ir.VectorType(ir.IntType(1), LANES)


def _pointers(element: ir.Type) -> ir.VectorType:
    return ir.VectorType(element.as_pointer(), LANES)


def _intrinsic(builder, name: str, ret: ir.Type, *params: ir.Type):
    return cgutils.get_or_insert_function(builder.module, ir.FunctionType(ret, list(params)), name)


#: (vector type, intrinsic suffix, alignment in bytes) of each element type gathered here
_GATHERED = {_F32: (_VF32, "v8f32", 4), _F64: (_VF64, "v8f64", 8), _I8: (_VI8, "v8i8", 1)}


def _gather(builder, element: ir.Type, addresses, mask, passthrough):
    """Masked gather of ``element`` values from integer byte addresses (llvmlite has no vector GEP)."""
    vector, suffix, align = _GATHERED[element]
    function = _intrinsic(
        builder, f"llvm.masked.gather.{suffix}.v{LANES}p0", vector, _pointers(element), _I32, _MASK, vector
    )
    pointers = builder.inttoptr(addresses, _pointers(element))
    return builder.call(function, [pointers, _I32(align), mask, passthrough])


def _scatter(builder, values, addresses, mask):
    function = _intrinsic(
        builder, f"llvm.masked.scatter.v{LANES}f64.v{LANES}p0", ir.VoidType(), _VF64, _pointers(_F64), _I32, _MASK
    )
    builder.call(function, [values, builder.inttoptr(addresses, _pointers(_F64)), _I32(8), mask])


@intrinsic
def radiance_block(typingctx, radiance, image, uv, state, start):
    """radiance[r] = bilinear lat-long lookup of ``image`` at uv[r] for r in start .. start + 7 where r is inside
    the arrays and state[r] != 0 (``SLOT_NONE``).  radiance (N, 3) float64, image (H, W, 3) float32 with H >= 2,
    uv (N, 2) float64, state (N,) int8, all C-contiguous."""
    float64_2d = types.Array(types.float64, 2, "C")
    if not (
        radiance == float64_2d
        and image == types.Array(types.float32, 3, "C")
        and uv == float64_2d
        and state == types.Array(types.int8, 1, "C")
        and isinstance(start, types.Integer)
    ):
        return None

    def codegen(context, builder, signature, args):
        radiance_v, image_v, uv_v, state_v, start_v = args
        radiance_a = context.make_array(signature.args[0])(context, builder, radiance_v)
        image_a = context.make_array(signature.args[1])(context, builder, image_v)
        uv_a = context.make_array(signature.args[2])(context, builder, uv_v)
        state_a = context.make_array(signature.args[3])(context, builder, state_v)
        start_v = context.cast(builder, start_v, signature.args[4], types.int64)

        def same(t, x):
            return ir.Constant(t, [x] * LANES)

        def splat(value, t):
            lane0 = builder.insert_element(ir.Constant(t, None), value, _I32(0))
            return builder.shuffle_vector(lane0, ir.Constant(t, None), ir.Constant(ir.VectorType(_I32, LANES), [0] * 8))

        def address_of(array, byte_offsets):
            return builder.add(splat(builder.ptrtoint(array.data, _I64), _VI64), byte_offsets)

        def clamp(x, lo, hi):  # also maps NaN to lo (the compare is false for NaN)
            x = builder.select(builder.fcmp_ordered(">=", x, same(_VF64, lo)), x, same(_VF64, lo))
            return builder.select(builder.fcmp_ordered("<=", x, same(_VF64, hi)), x, same(_VF64, hi))

        # which lanes hold a live slot
        n = cgutils.unpack_tuple(builder, state_a.shape, 1)[0]
        slots = builder.add(splat(start_v, _VI64), ir.Constant(_VI64, list(range(LANES))))
        inside = builder.icmp_signed("<", slots, splat(n, _VI64))
        states = _gather(builder, _I8, address_of(state_a, slots), inside, same(_VI8, 0))
        live = builder.and_(inside, builder.icmp_signed("!=", states, same(_VI8, 0)))
        uv_at = address_of(uv_a, builder.mul(slots, same(_VI64, 16)))
        u = _gather(builder, _F64, uv_at, live, same(_VF64, 0.5))
        v = _gather(builder, _F64, builder.add(uv_at, same(_VI64, 8)), live, same(_VF64, 0.5))

        # texels and weights, as mappings.bilinear_latlong_weights: columns at u = (i + 0.5) / W, periodic; rows at
        # v = j / (H - 1), clamped
        h, w, _ = cgutils.unpack_tuple(builder, image_a.shape, 3)
        wv, hv = splat(w, _VI64), splat(h, _VI64)
        fx = builder.fsub(builder.fmul(clamp(u, -1.0, 2.0), builder.sitofp(wv, _VF64)), same(_VF64, 0.5))
        x0f = builder.call(_intrinsic(builder, "llvm.floor.v8f64", _VF64, _VF64), [fx])
        tx = builder.fsub(fx, x0f)
        x0 = builder.fptosi(x0f, _VI64)
        x0 = builder.select(builder.icmp_signed("<", x0, same(_VI64, 0)), builder.add(x0, wv), x0)
        x0 = builder.select(builder.icmp_signed(">=", x0, wv), builder.sub(x0, wv), x0)
        x1 = builder.add(x0, same(_VI64, 1))
        x1 = builder.select(builder.icmp_signed("<", x1, wv), x1, same(_VI64, 0))
        fy = builder.fmul(clamp(v, 0.0, 1.0), builder.sitofp(builder.sub(hv, same(_VI64, 1)), _VF64))
        last = builder.sub(hv, same(_VI64, 2))
        y0 = builder.fptosi(fy, _VI64)
        y0 = builder.select(builder.icmp_signed("<", y0, last), y0, last)
        ty = builder.fsub(fy, builder.sitofp(y0, _VF64))
        y1 = builder.add(y0, same(_VI64, 1))
        corners = [builder.mul(builder.add(builder.mul(y, wv), x), same(_VI64, 12)) for y in (y0, y1) for x in (x0, x1)]
        one_tx, one_ty = builder.fsub(same(_VF64, 1.0), tx), builder.fsub(same(_VF64, 1.0), ty)
        radiance_at = address_of(radiance_a, builder.mul(slots, same(_VI64, 24)))
        for c in range(3):
            texels = []
            for corner in corners:
                at = address_of(image_a, builder.add(corner, same(_VI64, 4 * c)))
                texels.append(builder.fpext(_gather(builder, _F32, at, live, same(_VF32, 0.0)), _VF64))
            # mappings._bilerp: (1 - ty) ((1 - tx) t00 + tx t01) + ty ((1 - tx) t10 + tx t11)
            top = builder.fadd(builder.fmul(one_tx, texels[0]), builder.fmul(tx, texels[1]))
            bottom = builder.fadd(builder.fmul(one_tx, texels[2]), builder.fmul(tx, texels[3]))
            value = builder.fadd(builder.fmul(one_ty, top), builder.fmul(ty, bottom))
            _scatter(builder, value, builder.add(radiance_at, same(_VI64, 8 * c)), live)
        return context.get_dummy_value()

    return types.void(radiance, image, uv, state, start), codegen


@jit_parallel
def _probe(radiance, image, uv, state):
    for block in prange((state.shape[0] + LANES - 1) // LANES):
        radiance_block(radiance, image, uv, state, block * LANES)


_WORKS: list[bool] = []


def compiles() -> bool:
    """Whether this Numba and LLVM build the 8-lane lookup and it returns a known answer.  The intrinsics' names
    carry LLVM's pointer mangling (``v8p0``: opaque pointers, every LLVM that current Numba uses); an older LLVM
    that rejects them makes the renderer keep the scalar stage instead of failing.  Checked once per process."""
    if not _WORKS:
        try:
            image = np.arange(2 * 2 * 3, dtype=np.float32).reshape(2, 2, 3)
            radiance = np.zeros((3, 3))
            uv = np.array([[0.25, 0.0], [0.5, 0.5], [0.75, 1.0]])  # texel centres in u: no interpolation there
            _probe(radiance, image, uv, np.array([1, 0, 1], np.int8))
            expected = np.array([[0.0, 1.0, 2.0], [0.0, 0.0, 0.0], [9.0, 10.0, 11.0]])
            _WORKS.append(bool(np.array_equal(radiance, expected)))
        except Exception:  # an LLVM that does not know the intrinsics as named: the scalar stage renders instead
            _WORKS.append(False)
    return _WORKS[0]


def applies(image: np.ndarray, lookup_is_bilinear: bool) -> bool:
    """Whether :func:`radiance_block` can look ``image`` up: bilinear lookups of a C-contiguous float32 (H, W, 3)
    map with at least two rows (a one-row map has no row pair to interpolate; the scalar lookup handles it), on a
    Numba that compiles it."""
    return (
        lookup_is_bilinear
        and image.dtype == np.float32
        and image.ndim == 3
        and image.shape[0] >= 2
        and image.shape[2] == 3
        and image.flags.c_contiguous
        and compiles()
    )
