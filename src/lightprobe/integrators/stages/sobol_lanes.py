"""The camera samples' shading-slot random numbers under the ``sobol`` sampler, eight slots at a time, as vector IR.

The shading setup draws three numbers per slot -- the 2D pair ``uniform_2d(rj, 2 + 3 slot)`` and the 1D choice
``uniform(rj, 4 + 3 slot)`` of :func:`lightprobe.integrators.techniques.technique_slot`'s (state, slot) -- and in
scalar code they are a fifth of the setup stage: chains of 64-bit multiplies (SplitMix64) and the Laine-Karras
hash, a few hundred integer operations per slot that wait on one another.  :func:`slot_numbers_run` computes them
for 8 slots at once in 8 integer lanes (AVX-512 multiplies 8 x 64 bits per instruction), the slots of several camera
samples side by side where a camera sample has fewer than 8 (decisions.md 132).  Integer arithmetic is exact, so
every lane gives the scalar code's bits; the float conversion ``x * 2^-32`` of a 32-bit integer is exact too.  Tested
against :mod:`lightprobe.sampling.rng` number for number (``tests/integrators/stages/test_sobol_lanes.py``).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ...sampling.rng import _DIM, _GOLDEN, _INV32, _LK1, _LK2, _LK3, _M1, _M2, _PIXEL, _SUPERSET
from ...simd import LANES, Lanes

__all__ = ["LANES", "camera_numbers_block", "slot_numbers_run"]

F64, I32, I64 = ir.DoubleType(), ir.IntType(32), ir.IntType(64)
VI32, VI64, VF64 = ir.VectorType(I32, LANES), ir.VectorType(I64, LANES), ir.VectorType(F64, LANES)


def _u64(x) -> int:
    return int(x) & 0xFFFFFFFFFFFFFFFF


class _Integers:
    """The rng module's integer functions on 8 lanes of int64 (wrapping arithmetic, as NumPy's uint64)."""

    def __init__(self, lanes: Lanes):
        self.v, self.b = lanes, lanes.b

    def c64(self, x):
        return ir.Constant(VI64, [_u64(x)] * LANES)

    def c32(self, x):
        return ir.Constant(VI32, [int(x) & 0xFFFFFFFF] * LANES)

    def mix(self, z):
        """rng._mix: SplitMix64's finaliser."""
        b = self.b
        z = b.mul(b.xor(z, b.lshr(z, self.c64(30))), self.c64(_M1))
        z = b.mul(b.xor(z, b.lshr(z, self.c64(27))), self.c64(_M2))
        return b.xor(z, b.lshr(z, self.c64(31)))

    def reverse32(self, x32):
        """rng._reverse32 of 32-bit lanes."""
        function = cgutils.get_or_insert_function(
            self.b.module, ir.FunctionType(VI32, [VI32]), f"llvm.bitreverse.v{LANES}i32"
        )
        return self.b.call(function, [x32])

    def laine_karras(self, x32, seed64):
        """rng._laine_karras: every operation is mod 2^32 there (``& 0xFFFFFFFF`` after each), so it runs in 32-bit
        lanes, whose wrapping gives the same low 32 bits."""
        b = self.b
        seed = b.trunc(seed64, VI32)
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
        return self.b.fmul(self.b.uitofp(x32, VF64), ir.Constant(VF64, [_INV32] * LANES))

    def pair_hash(self, pkey, index, pair):
        """rng._pair_scramble: the hash of (pixel key, Sobol' pair, index's high half) and the shuffled index."""
        b = self.b
        high = b.mul(b.lshr(index, self.c64(32)), self.c64(_GOLDEN))
        h = self.mix(b.add(b.add(pkey, b.mul(b.add(pair, self.v.i(1)), self.c64(_DIM))), high))
        return h, self.owen(b.trunc(index, VI32), h)

    def sobol_x(self, h, shuffled):
        """rng._sobol_x."""
        return self.to_unit(self.reverse32(self.laine_karras(shuffled, self.b.lshr(h, self.c64(32)))))

    def pass_sample(self, pixels, seed, spp_pass, sample_start, k):
        """(pixel key, sample index) of camera samples k (int64 lanes) of a pass: ``sample_state(sobol, seed,
        pixels[k // spp_pass], sample_start + k % spp_pass)``'s; ``pixels`` the pass's pixel array (a Numba array
        struct), the rest int64 lanes."""
        b, v = self.b, self.v
        q = v.quotient(k, spp_pass)  # the camera sample's pixel in the pass
        pixel = v.gather(I64, v.address(pixels, q, 8))
        sample = b.add(sample_start, b.sub(k, b.mul(q, spp_pass)))
        return self.mix(b.add(b.mul(seed, self.c64(_GOLDEN)), b.mul(pixel, self.c64(_PIXEL)))), sample  # pixel_key

    def sobol_2d(self, pkey, index, pair):
        """Both coordinates of Sobol' pair ``pair`` for sample ``index`` (rng.uniform_2d): x as rng._sobol_x, y as
        rng._sobol_y_scrambled.  rng._sobol_y is reverse32 of a superset sum z, and owen_scramble begins by
        reversing its argument, so y's scrambled value is reverse32(laine_karras(z)) with no reversal before."""
        b = self.b
        h, shuffled = self.pair_hash(pkey, index, pair)
        z = shuffled
        for shift, mask in _SUPERSET:
            z = b.xor(z, b.and_(b.lshr(z, self.c32(shift)), self.c32(mask)))
        y = self.reverse32(self.laine_karras(z, self.mix(h)))
        return self.sobol_x(h, shuffled), self.to_unit(y)


def _slot_numbers(n: _Integers, pkey, sample, mis, n_bsdf, m, j):
    """(u0, u1, u2) of shading slot ``j`` (int64 lanes) of camera samples with pixel keys ``pkey`` and sample indices
    ``sample``: the numbers ``technique_slot(state, strategy, n_bsdf, m - n_bsdf, j)`` gives its slot,
    ``uniform_2d(rj, 2 + 3 slot)`` and ``uniform(rj, 4 + 3 slot)``; ``mis`` (i1 lanes) whether the strategy is MIS."""
    v, b = n.v, n.b
    # techniques.technique_slot + rng.group_slot: under MIS the BSDF slots are one group and the light slots another;
    # otherwise all m slots are one.  Member jj of a group of size g takes sample index sample g + jj and the
    # dimensions of the group's first slot.
    light = b.and_(mis, b.icmp_signed(">=", j, n_bsdf))
    group_first = b.select(light, n_bsdf, v.i(0))
    group_size = b.select(mis, b.select(light, b.sub(m, n_bsdf), n_bsdf), m)
    index = b.add(b.mul(sample, group_size), b.sub(j, group_first))
    # the 2D pair: dimensions 2 + 3 slot and 3 + 3 slot are Sobol' pair 1 + 2 slot (rng._pair_of)
    u0, u1 = n.sobol_2d(pkey, index, b.add(v.i(1), b.mul(v.i(2), group_first)))
    # the 1D choice: dimension 4 + 3 slot is the first coordinate of Sobol' pair 2 + 2 slot
    h2, shuffled2 = n.pair_hash(pkey, index, b.add(v.i(2), b.mul(v.i(2), group_first)))
    return u0, u1, n.sobol_x(h2, shuffled2)


@intrinsic
def slot_numbers_run(typingctx, out, seed, pixels, spp_pass, sample_start, material, mis, n_bsdf, m, k0, count, f):
    """out[f + i] = (u0, u1, u2) for the 8 flat slots f + i = (k - k0) m + j, i = 0 .. 7, of camera samples k = k0 ..
    k0 + count - 1 of a pass (pixel ``pixels[k // spp_pass]``, sample index ``sample_start + k % spp_pass``, as
    ``sample_state(sobol, seed, ...)``): slot j's ``uniform_2d(rj, 2 + 3 slot)`` and ``uniform(rj, 4 + 3 slot)`` of
    ``technique_slot(state, strategy, n_bsdf, m - n_bsdf, j)``, ``mis`` saying whether the strategy is MIS.  The
    slots of several camera samples share the lanes (a camera sample of 2 or 3 slots filled 2 or 3 of 8 before), and
    a block where no camera sample is shaded (``material[k] < 0``) computes nothing.  Rows past the range stay
    untouched.  out (N, 3) float64 C-contiguous, pixels and material (P,) / (K,) int64, mis a boolean, the rest
    integers."""
    integer = (seed, spp_pass, sample_start, n_bsdf, m, k0, count, f)
    if not (
        out == types.Array(types.float64, 2, "C")
        and all(
            isinstance(a, types.Array) and (a.dtype, a.ndim, a.layout) == (types.int64, 1, "C")
            for a in (pixels, material)
        )
        and isinstance(mis, types.Boolean)
        and all(isinstance(t, types.Integer) for t in integer)
    ):
        return None
    signature_args = (out, seed, pixels, spp_pass, sample_start, material, mis, n_bsdf, m, k0, count, f)

    def codegen(context, builder, signature, args):
        out_a = context.make_array(signature.args[0])(context, builder, args[0])
        pixels_a = context.make_array(signature.args[2])(context, builder, args[2])
        material_a = context.make_array(signature.args[5])(context, builder, args[5])
        v, b = Lanes(builder), builder
        n = _Integers(v)

        def scalar(i):
            return context.cast(b, args[i], signature.args[i], types.int64)

        seed_v, spp_v, first_sample_v, n_bsdf_v, m_v, k0_v, count_v = (
            v.splat(scalar(i), VI64) for i in (1, 3, 4, 7, 8, 9, 10)
        )
        mis_v = v.splat(context.cast(b, args[6], signature.args[6], types.boolean), ir.VectorType(ir.IntType(1), LANES))
        flat = b.add(v.splat(scalar(11), VI64), ir.Constant(VI64, list(range(LANES))))
        q = v.quotient(flat, m_v)  # the camera sample's place in the run
        j = b.sub(flat, b.mul(q, m_v))
        live = b.icmp_signed("<", q, count_v)
        k = b.add(k0_v, v.imin(q, b.sub(count_v, v.i(1))))  # clipped for reading
        shaded = b.and_(live, b.icmp_signed(">=", v.gather(I64, v.address(material_a, k, 8)), v.i(0)))
        done = v.skip_unless(shaded)
        pkey, sample = n.pass_sample(pixels_a, seed_v, spp_v, first_sample_v, k)
        u0, u1, u2 = _slot_numbers(n, pkey, sample, mis_v, n_bsdf_v, m_v, j)
        # the 8 rows (u0, u1, u2) are 24 consecutive doubles: one vector store (a scatter per number measured the
        # same in the render, 3.0-3.1 s of setup)
        v.store_run([u0, u1, u2], b.gep(out_a.data, [b.mul(scalar(11), I64(3))]), live)
        v.end_skip(done)
        return context.get_dummy_value()

    return types.void(*signature_args), codegen


@intrinsic
def camera_numbers_block(typingctx, dirs, seed, pixels, spp_pass, sample_start, start):
    """dirs[k, 0:2] = ``uniform_2d(sample_state(sobol, seed, pixels[k // spp_pass], sample_start + k % spp_pass),
    0)`` -- the camera ray's position in its pixel -- for camera samples k = start .. start + 7 below len(dirs), and
    dirs[k, 2] = 0 (the direction replaces the row).  dirs (N, 3) float64 C-contiguous, pixels (P,) int64, the rest
    integers."""
    if not (
        dirs == types.Array(types.float64, 2, "C")
        and isinstance(pixels, types.Array)
        and (pixels.dtype, pixels.ndim, pixels.layout) == (types.int64, 1, "C")
        and all(isinstance(t, types.Integer) for t in (seed, spp_pass, sample_start, start))
    ):
        return None
    signature_args = (dirs, seed, pixels, spp_pass, sample_start, start)

    def codegen(context, builder, signature, args):
        dirs_a = context.make_array(signature.args[0])(context, builder, args[0])
        pixels_a = context.make_array(signature.args[2])(context, builder, args[2])
        v, b = Lanes(builder), builder
        n = _Integers(v)

        def scalar(i):
            return context.cast(b, args[i], signature.args[i], types.int64)

        seed_v, spp_v, first_sample_v = (v.splat(scalar(i), VI64) for i in (1, 3, 4))
        _, inside, k = v.slots(scalar(5), cgutils.unpack_tuple(b, dirs_a.shape, 2)[0])
        pkey, sample = n.pass_sample(pixels_a, seed_v, spp_v, first_sample_v, k)
        u0, u1 = n.sobol_2d(pkey, sample, v.i(0))  # dimensions 0 and 1: Sobol' pair 0
        first = b.extract_element(k, I32(0))
        v.store_run([u0, u1, v.f(0.0)], b.gep(dirs_a.data, [b.mul(first, I64(3))]), inside)
        return context.get_dummy_value()

    return types.void(*signature_args), codegen
