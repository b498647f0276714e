"""A camera sample's shading-slot random numbers under the ``sobol`` sampler, eight slots at a time, as vector IR.

The shading setup draws three numbers per slot -- the 2D pair ``uniform_2d(rj, 2 + 3 slot)`` and the 1D choice
``uniform(rj, 4 + 3 slot)`` of :func:`lightprobe.integrators.techniques.technique_slot`'s (state, slot) -- and in
scalar code they are a fifth of the setup stage: chains of 64-bit multiplies (SplitMix64) and the Laine-Karras
hash, a few hundred integer operations per slot that wait on one another.  :func:`slot_numbers_block` computes them
for 8 slots at once in 8 integer lanes (AVX-512 multiplies 8 x 64 bits per instruction).  Integer arithmetic is
exact, so every lane gives the scalar code's bits; the float conversion ``x * 2^-32`` of a 32-bit integer is exact
too.  Tested against :mod:`lightprobe.sampling.rng` number for number (``tests/sampling/test_sobol_lanes.py``).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ..emitters.envmap_lanes import LANES, _Lanes
from .rng import _DIM, _GOLDEN, _INV32, _LK1, _LK2, _LK3, _M1, _M2, _SOBOL_Y

__all__ = ["LANES", "SOBOL_Y", "slot_numbers_block"]

#: Sobol's second dimension as four byte tables (``rng._sobol_y_tables``), passed to the intrinsic
SOBOL_Y = _SOBOL_Y

_F64, _I32, _I64 = ir.DoubleType(), ir.IntType(32), ir.IntType(64)
_VI32, _VI64, _VF64 = ir.VectorType(_I32, LANES), ir.VectorType(_I64, LANES), ir.VectorType(_F64, LANES)


def _u64(x) -> int:
    return int(x) & 0xFFFFFFFFFFFFFFFF


class _Integers:
    """The rng module's integer functions on 8 lanes of int64 (wrapping arithmetic, as NumPy's uint64)."""

    def __init__(self, lanes: _Lanes):
        self.v, self.b = lanes, lanes.b

    def c64(self, x):
        return ir.Constant(_VI64, [_u64(x)] * LANES)

    def c32(self, x):
        return ir.Constant(_VI32, [int(x) & 0xFFFFFFFF] * LANES)

    def mix(self, z):
        """rng._mix: SplitMix64's finaliser."""
        b = self.b
        z = b.mul(b.xor(z, b.lshr(z, self.c64(30))), self.c64(_M1))
        z = b.mul(b.xor(z, b.lshr(z, self.c64(27))), self.c64(_M2))
        return b.xor(z, b.lshr(z, self.c64(31)))

    def reverse32(self, x32):
        """rng._reverse32 of 32-bit lanes."""
        function = cgutils.get_or_insert_function(
            self.b.module, ir.FunctionType(_VI32, [_VI32]), f"llvm.bitreverse.v{LANES}i32"
        )
        return self.b.call(function, [x32])

    def laine_karras(self, x32, seed64):
        """rng._laine_karras: every operation is mod 2^32 there (``& 0xFFFFFFFF`` after each), so it runs in 32-bit
        lanes, whose wrapping gives the same low 32 bits."""
        b = self.b
        seed = b.trunc(seed64, _VI32)
        x = b.xor(x32, b.mul(x32, self.c32(_LK1)))
        x = b.add(x, seed)
        x = b.mul(x, b.or_(b.lshr(seed, self.c32(16)), self.c32(1)))
        x = b.xor(x, b.mul(x, self.c32(_LK2)))
        return b.xor(x, b.mul(x, self.c32(_LK3)))

    def owen(self, x32, seed64):
        """rng.owen_scramble."""
        return self.reverse32(self.laine_karras(self.reverse32(x32), seed64))

    def to_unit(self, x32):
        """float(x) * 2^-32 for a 32-bit value: exact."""
        return self.b.fmul(self.b.uitofp(x32, _VF64), ir.Constant(_VF64, [_INV32] * LANES))


@intrinsic
def slot_numbers_block(typingctx, out, sobol_y, pkey, sample, mis, n_bsdf, m, row, first_slot):
    """out[row + j - first_slot] = (u0, u1, u2) for shading slots j = first_slot .. first_slot + 7 below m of one
    camera sample whose ``sample_state`` under ``sobol`` has pixel key ``pkey`` and sample index ``sample``: the
    numbers ``technique_slot(state, strategy, n_bsdf, m - n_bsdf, j)`` gives its slot, ``uniform_2d(rj, 2 + 3 slot)``
    and ``uniform(rj, 4 + 3 slot)``, where ``mis`` says whether the strategy is MIS.  out (N, 3) float64
    C-contiguous, sobol_y (4, 256) uint64 (:data:`SOBOL_Y`), pkey uint64, mis a boolean, the rest integers."""
    if not (
        out == types.Array(types.float64, 2, "C")
        and isinstance(sobol_y, types.Array)  # a module-level global is a read-only array to Numba
        and (sobol_y.dtype, sobol_y.ndim, sobol_y.layout) == (types.uint64, 2, "C")
        and pkey == types.uint64
        and isinstance(mis, types.Boolean)
        and all(isinstance(t, types.Integer) for t in (sample, n_bsdf, m, row, first_slot))
    ):
        return None
    signature_args = (out, sobol_y, pkey, sample, mis, n_bsdf, m, row, first_slot)

    def codegen(context, builder, signature, args):
        out_a = context.make_array(signature.args[0])(context, builder, args[0])
        table_a = context.make_array(signature.args[1])(context, builder, args[1])
        v, b = _Lanes(builder), builder
        n = _Integers(v)

        def scalar(i):
            return context.cast(b, args[i], signature.args[i], types.int64)

        sample_v, n_bsdf_v, m_v, first_v = (v.splat(scalar(i), _VI64) for i in (3, 5, 6, 8))
        mis = v.splat(context.cast(b, args[4], signature.args[4], types.boolean), ir.VectorType(ir.IntType(1), LANES))
        pkey_v = v.splat(args[2], _VI64)
        j = b.add(first_v, ir.Constant(_VI64, list(range(LANES))))
        live = b.icmp_signed("<", j, m_v)
        # techniques.technique_slot + rng.group_slot: under MIS the BSDF slots are one group and the light slots
        # another; otherwise all m slots are one.  Member jj of a group of n takes sample index sample n + jj and
        # the dimensions of the group's first slot.
        light = b.and_(mis, b.icmp_signed(">=", j, n_bsdf_v))
        group_first = b.select(light, n_bsdf_v, v.i(0))
        group_size = b.select(mis, b.select(light, b.sub(m_v, n_bsdf_v), n_bsdf_v), m_v)
        index = b.add(b.mul(sample_v, group_size), b.sub(j, group_first))
        high = b.mul(b.lshr(index, n.c64(32)), n.c64(_GOLDEN))
        low32 = b.trunc(index, _VI32)

        def pair_hash(pair):  # rng._pair_scramble's hash and shuffled index
            h = n.mix(b.add(b.add(pkey_v, b.mul(b.add(pair, v.i(1)), n.c64(_DIM))), high))
            return h, n.owen(low32, h)

        def sobol_x(h, shuffled):  # rng._sobol_x
            return n.to_unit(n.reverse32(n.laine_karras(shuffled, b.lshr(h, n.c64(32)))))

        # the 2D pair: dimensions 2 + 3 slot and 3 + 3 slot are Sobol' pair 1 + 2 slot (rng._pair_of)
        h, shuffled = pair_hash(b.add(v.i(1), b.mul(v.i(2), group_first)))
        u0 = sobol_x(h, shuffled)
        wide = b.zext(shuffled, _VI64)  # rng._sobol_y: four byte tables
        y = None
        for q in range(4):
            byte = b.and_(b.lshr(wide, v.i(8 * q)), v.i(255))
            entry = v.gather(_I64, v.address(table_a, b.add(byte, v.i(256 * q)), 8))
            y = entry if y is None else b.xor(y, entry)
        u1 = n.to_unit(n.owen(b.trunc(y, _VI32), n.mix(h)))
        # the 1D choice: dimension 4 + 3 slot is the first coordinate of Sobol' pair 2 + 2 slot
        h2, shuffled2 = pair_hash(b.add(v.i(2), b.mul(v.i(2), group_first)))
        u2 = sobol_x(h2, shuffled2)
        # the 8 rows (u0, u1, u2) are 24 consecutive doubles: one masked vector store (a scatter per number measured
        # the same in the render, 3.0-3.1 s of setup)
        v.store_run([u0, u1, u2], b.gep(out_a.data, [b.mul(scalar(7), _I64(3))]), live)
        return context.get_dummy_value()

    return types.void(*signature_args), codegen
