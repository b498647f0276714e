"""The environment map's work for eight shading slots at a time, as vector LLVM IR: radiance lookups, samples of
the bilinear density, and directions' lat-long coordinates with the density there.

Numba compiles the renderer's kernels one slot at a time: its vectoriser gives up on any loop that reads a table
(docs/decisions.md 35), so each lookup's texel reads and each sample's bisections run in scalar code.  Here each is
a Numba ``@intrinsic`` that emits the whole operation for 8 slots as vector IR: the arithmetic in 8 float64 lanes,
the table reads as 8 loads whose addresses come from the lanes, the writes as masked scatters (or, where a block's
slots are consecutive, masked vector stores).  In the peer render the environment's stages take 4.8 s against
8.3-8.9 one slot at a time (decisions.md 41-47; the lookup alone: ``benchmarks/simd_lookup.py``).

Every lane computes what the scalar code computes, operation for operation and in its order, with the kernels'
fast-math flags (``_numba.FASTMATH``): :func:`radiance_block` is :func:`lightprobe.emitters.envmap.env_lookup` for a
bilinear lat-long map, :func:`env_sample_block` is ``wavefront._env_sample_stage`` for the bilinear density (its
searches started from guide tables whose brackets it checks first, so that they find the same indices),
:func:`env_coords_block` is ``wavefront._env_coords_stage`` (its atan2 and acos as Cephes' polynomials in the
lanes, within 2 ulp of the C library's the scalar stage calls).  On the machine measured the renders are the same
bits in float32; where LLVM fuses a multiply-add in one and not the other they may differ by an ulp (the tests
allow for it).

Lanes of dead slots and lanes past a pass's last slot write nothing (a block with no live lane branches past its
work, decisions.md 54), and every slot of a pass goes through the lanes whatever the pass size, so the image does
not depend on how slots fall into blocks.  Each block prefetches what the block 16 ahead will read and write
(decisions.md 53).  A lane past the end reads the last slot (or, in a masked vector load, nothing), and a
coordinate outside the lookup's domain (a NaN, or far outside [0, 1]: a dead slot's stale value) is clamped before
it becomes an index, since a vector lane cannot take the scalar code's slow path and an index from a NaN would
address any memory.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ..._numba import jit
from ...simd import (
    F64,
    I8,
    I32,
    I64,
    LANES,
    MASK,
    VF64,
    VI8,
    VI64,
    Lanes,
    llvm_function,
)
from ..techniques import SLOT_BSDF, SLOT_LIGHT, SLOT_NONE

_TWO_PI = 2.0 * math.pi
_TWO_PI_SQUARED = 2.0 * math.pi * math.pi  # folded as the scalar code's 2.0 * math.pi * math.pi * sin_theta is


@intrinsic
def radiance_block(typingctx, radiance, image, uv, state, start):
    """radiance[r] = bilinear lat-long lookup of ``image`` at uv[r] for r in start .. start + 7 where r is inside
    the arrays and state[r] is not SLOT_NONE.  radiance (N, 3) float64, image (H, W, 3) float32 with H >= 2, uv (N,
    2) float64, state (N,) int8, all C-contiguous."""
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
        radiance_a, image_a, uv_a, state_a = (
            context.make_array(t)(context, builder, value)
            for t, value in zip(signature.args[:4], args[:4], strict=True)
        )
        v, b = Lanes(builder), builder
        start_v = context.cast(b, args[4], signature.args[4], types.int64)
        _, inside, read = v.slots(start_v, cgutils.unpack_tuple(b, state_a.shape, 1)[0])
        # the block's 8 slots are consecutive: its states, coordinates and radiances are contiguous runs, read and
        # written by masked vector loads and stores (a lane past the end reads and writes nothing)
        first = v.b.extract_element(read, I32(0))
        states = v.load_run(I8, b.gep(state_a.data, [first]), inside, 1, 0)
        live = b.and_(inside, b.icmp_signed("!=", states, ir.Constant(VI8, [SLOT_NONE] * LANES)))
        u, vv = v.load_run(F64, b.gep(uv_a.data, [b.mul(first, I64(2))]), inside, 2, 0.5)
        # mappings.bilinear_latlong_weights: columns at u = (i + 0.5) / W, periodic; rows at v = j / (H - 1), clamped
        h, w, _ = cgutils.unpack_tuple(b, image_a.shape, 3)
        wv, hv = v.splat(w, VI64), v.splat(h, VI64)
        # prefetched: the two texel rows at the slots PREFETCH_BLOCKS blocks ahead (their coordinates a contiguous run;
        # the column without the half-texel shift, near enough for a prefetch, which never faults)
        n_slots = cgutils.unpack_tuple(b, state_a.shape, 1)[0]
        ahead = b.add(first, I64(PREFETCH_BLOCKS * LANES))
        ahead = b.select(b.icmp_signed("<", ahead, b.sub(n_slots, I64(LANES))), ahead, first)
        ua, va = v.load_run(F64, b.gep(uv_a.data, [b.mul(ahead, I64(2))]), inside, 2, 0.5)
        xa = b.fptosi(v.mul(v.clamp(ua, 0.0, 1.0), v.to_f(wv)), VI64)
        xa = b.select(b.icmp_signed(">=", xa, wv), b.sub(xa, wv), xa)
        ya = v.imin(b.fptosi(v.mul(v.clamp(va, 0.0, 1.0), v.to_f(b.sub(hv, v.i(1)))), VI64), b.sub(hv, v.i(2)))
        prefetch = llvm_function(b, "llvm.prefetch.p0", ir.VoidType(), I8.as_pointer(), I32, I32, I32)
        texel_base = b.ptrtoint(image_a.data, I64)
        for yy in (ya, b.add(ya, v.i(1))):
            at = b.add(v.splat(texel_base, VI64), b.mul(b.add(b.mul(yy, wv), xa), v.i(12)))
            for lane in range(LANES):
                pointer = b.inttoptr(b.extract_element(at, I32(lane)), I8.as_pointer())
                b.call(prefetch, [pointer, I32(0), I32(3), I32(1)])
        skipped = v.skip_unless(live)
        # u clamped to [-1/2, 3/2] (a NaN to -1/2) so that one wrap below brings every column into [0, W); with
        # [-1, 2] a NaN's column was -1, a read before the image (caught by CI as a NaN radiance, once)
        fx = v.sub(v.mul(v.clamp(u, -0.5, 1.5), v.to_f(wv)), v.f(0.5))
        x0f = b.call(llvm_function(b, "llvm.floor.v8f64", VF64, VF64), [fx])
        tx = v.sub(fx, x0f)
        x0 = b.fptosi(x0f, VI64)
        x0 = b.select(b.icmp_signed("<", x0, v.i(0)), b.add(x0, wv), x0)
        x0 = b.select(b.icmp_signed(">=", x0, wv), b.sub(x0, wv), x0)
        x1 = b.add(x0, v.i(1))
        x1 = b.select(b.icmp_signed("<", x1, wv), x1, v.i(0))
        fy = v.mul(v.clamp(vv, 0.0, 1.0), v.to_f(b.sub(hv, v.i(1))))
        y0 = v.imin(b.fptosi(fy, VI64), b.sub(hv, v.i(2)))
        ty = v.sub(fy, v.to_f(y0))
        y1 = b.add(y0, v.i(1))
        corners = [b.mul(b.add(b.mul(y, wv), x), v.i(3)) for y in (y0, y1) for x in (x0, x1)]
        one_tx, one_ty = v.sub(v.f(1.0), tx), v.sub(v.f(1.0), ty)
        channels = []
        for c in range(3):
            t00, t01, t10, t11 = (v.load_f32(image_a, b.add(corner, v.i(c))) for corner in corners)
            # mappings._bilerp: (1 - ty) ((1 - tx) t00 + tx t01) + ty ((1 - tx) t10 + tx t11)
            top = v.add(v.mul(one_tx, t00), v.mul(tx, t01))
            bottom = v.add(v.mul(one_tx, t10), v.mul(tx, t11))
            channels.append(v.add(v.mul(one_ty, top), v.mul(ty, bottom)))
        v.store_run(channels, b.gep(radiance_a.data, [b.mul(first, I64(3))]), live)
        v.end_skip(skipped)
        return context.get_dummy_value()

    return types.void(radiance, image, uv, state, start), codegen


# --- what the sampling and coordinates lanes share -----------------------------------------------------------------
def _arguments_fit(names, values, dtypes, booleans=(), floats=()) -> bool:
    """Whether an intrinsic's argument types are the ones it is written for: arrays of ``dtypes`` (dtype, ndim),
    C-contiguous, the names in ``booleans`` and ``floats`` scalars of that kind, every other one an integer."""
    for name, t in zip(names, values, strict=True):
        if name in dtypes:
            dtype, ndim = dtypes[name]
            if not (isinstance(t, types.Array) and t.dtype == dtype and t.ndim == ndim and t.layout == "C"):
                return False
        elif not isinstance(t, types.Boolean if name in booleans else types.Float if name in floats else types.Integer):
            return False
    return True


class _Arguments:
    """An intrinsic's arguments by name inside its codegen: the arrays, their shapes and integers as int64 lanes."""

    def __init__(self, names, context, builder, signature, args):
        self.names, self.context, self.b, self.signature = names, context, builder, signature
        self.values = dict(zip(names, args, strict=True))
        self.arrays = {
            name: context.make_array(t)(context, builder, self.values[name])
            for name, t in zip(names, signature.args, strict=True)
            if isinstance(t, types.Array)
        }
        self.v = Lanes(builder)

    def scalar(self, name, to):
        return self.context.cast(self.b, self.values[name], self.signature.args[self.names.index(name)], to)

    def integer(self, name):
        return self.v.splat(self.scalar(name, types.int64), VI64)

    def shape(self, name, axis):
        ndim = self.signature.args[self.names.index(name)].ndim
        return self.v.splat(cgutils.unpack_tuple(self.b, self.arrays[name].shape, ndim)[axis], VI64)


def _numbered_slots(a: _Arguments):
    """(camera sample k, slot, inside) of lanes ``start .. start + 7`` when a pass's slots are numbered over its
    camera samples: lane q is slot ``first + q % count`` of camera sample ``q // count``, so that every lane holds a
    slot of the kind a stage serves.  Lanes past the end read the last such slot (and write nothing), so that every
    load has a valid address and needs no mask."""
    v, b = a.v, a.b
    m_v, first_v, count_v = a.integer("m"), a.integer("first"), a.integer("count")
    q = b.add(a.integer("start"), ir.Constant(VI64, list(range(LANES))))
    n_q = b.mul(a.shape("material", 0), count_v)
    inside = b.icmp_signed("<", q, n_q)
    q = v.imin(q, b.sub(n_q, v.i(1)))
    k = v.quotient(q, count_v)
    return k, b.add(b.add(b.mul(k, m_v), first_v), b.sub(q, b.mul(k, count_v))), inside


# How far ahead the numbered stages prefetch their slots' rows, and the radiance lanes their texels (decisions.md
# 53): a numbered block holds a camera sample's few slots of one kind, read and written by 8 scalar accesses, a
# pattern the hardware prefetchers do not follow; a lookup's texels are wherever its direction points.
PREFETCH_BLOCKS = 16


def _prefetch_ahead(a: _Arguments, streams):
    """Prefetch, for the camera samples of the first and the last lane ``PREFETCH_BLOCKS`` blocks ahead, the rows
    of ``streams``: (array name, bytes per row, per "slot" or per camera sample "k", whether it is written).  A
    camera sample's rows of one kind are consecutive (its slots first .. first + count - 1), so the first line and the
    last of them cover the stream.  Prefetches never fault: the rows past the end are clamped for tidiness only."""
    b = a.b
    count, m, first, start = (a.scalar(name, types.int64) for name in ("count", "m", "first", "start"))
    n_k = cgutils.unpack_tuple(b, a.arrays["material"].shape, 1)[0]
    prefetch = llvm_function(b, "llvm.prefetch.p0", ir.VoidType(), I8.as_pointer(), I32, I32, I32)
    for lane in (0, LANES - 1):
        k = b.sdiv(b.add(start, I64(PREFETCH_BLOCKS * LANES + lane)), count)
        k = b.select(b.icmp_signed("<", k, n_k), k, b.sub(n_k, I64(1)))
        for name, size, per, written in streams:
            row = b.add(b.mul(k, m), first) if per == "slot" else k
            rows = count if per == "slot" else I64(1)
            at = b.add(b.ptrtoint(a.arrays[name].data, I64), b.mul(row, I64(size)))
            last = b.add(at, b.sub(b.mul(rows, I64(size)), I64(1)))
            for address in (at, last) if size > 1 else (at,):
                pointer = b.inttoptr(address, I8.as_pointer())
                b.call(prefetch, [pointer, I32(1 if written else 0), I32(3), I32(1)])


def _compensation(a: _Arguments, k):
    """Per lane, whether camera sample k's material takes the compensated density, and the luminance offset."""
    v, b = a.v, a.b
    kind = v.gather(I64, v.address(a.arrays["material"], k, 8))
    compensated = b.icmp_signed(
        "!=", v.gather(I8, v.address(a.arrays["compensate"], kind, 1)), ir.Constant(VI8, [0] * LANES)
    )
    return compensated, b.select(compensated, v.splat(a.values["comp_offset"], VF64), v.f(0.0))


def _pick(a: _Arguments, compensated, name_comp, name_plain):
    """Per lane, the compensated or the plain table's base address."""
    v, b = a.v, a.b
    comp_base = v.splat(b.ptrtoint(a.arrays[name_comp].data, I64), VI64)
    plain_base = v.splat(b.ptrtoint(a.arrays[name_plain].data, I64), VI64)
    return b.select(compensated, comp_base, plain_base)


def _node_weight(a: _Arguments, offset):
    """envmap_bilinear.node_weight of the lanes' density (``offset`` subtracted from the luminance)."""
    v, b = a.v, a.b
    h, width = a.shape("luminance", 0), a.shape("luminance", 1)

    def weight(j, i):
        jj = v.imin(j, b.sub(h, v.i(1)))
        ii = b.select(b.icmp_signed("<", i, width), i, b.sub(i, width))
        value = v.sub(v.load_f32(a.arrays["luminance"], b.add(b.mul(jj, width), ii)), offset)
        return b.select(v.gt(value, v.f(0.0)), v.mul(value, v.load_f64(a.arrays["sines"], j)), v.f(0.0))

    return weight


# --- environment samples from the bilinear density ----------------------------------------------------------------
def _invert_linear_lanes(v: Lanes, a, c, m):
    """envmap_bilinear._invert_linear: t in [0, 1] with a t + (c - a) t^2 / 2 = m."""
    discriminant = v.add(v.mul(a, a), v.mul(v.mul(v.f(2.0), v.sub(c, a)), m))
    den = v.add(a, v.sqrt(v.fmax(discriminant, v.f(0.0))))
    t = v.fmin(v.fmax(v.div(v.mul(v.f(2.0), m), den), v.f(0.0)), v.f(1.0))
    return v.b.select(v.le(den, v.f(0.0)), v.f(0.0), t)


def _small_cos_sin_lanes(v: Lanes, d):
    """envmap_bilinear._small_cos_sin, term by term."""
    d2 = v.mul(d, d)
    c = v.sub(v.f(1.0 / 40320.0), v.div(d2, v.f(3628800.0)))
    c = v.sub(v.f(1.0 / 720.0), v.mul(d2, c))
    c = v.sub(v.f(1.0 / 24.0), v.mul(d2, c))
    c = v.sub(v.f(0.5), v.mul(d2, c))
    c = v.sub(v.f(1.0), v.mul(d2, c))
    s = v.sub(v.f(1.0 / 5040.0), v.div(d2, v.f(362880.0)))
    s = v.sub(v.f(1.0 / 120.0), v.mul(d2, s))
    s = v.sub(v.f(1.0 / 6.0), v.mul(d2, s))
    s = v.mul(d, v.sub(v.f(1.0), v.mul(d2, s)))
    return c, s


# Cephes' atan (atan.c, S. L. Moshier): atan(x) = x + x z P(z) / Q(z), z = x^2, for 0 <= x <= 0.66
_ATAN_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
           -1.228866684490136173410e2, -6.485021904942025371773e1)  # fmt: skip
_ATAN_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
           4.853903996359136964868e2, 1.945506571482613964425e2)  # fmt: skip
_ATAN_MOREBITS = 6.123233995736765886130e-17  # pi/4's double rounding error, added back (atan.c)


def _atan2_lanes(v: Lanes, y, x):
    """atan2(y, x) in the lanes, within 2 ulp of the C library's (a test checks 4e-16 rad on directions, poles
    included): |y| / |x| or its inverse, whichever is in [0, 1], through Cephes' atan -- its rational function
    up to 0.66, pi/4 + atan((t - 1) / (t + 1)) above -- then the octant's reflections, by the signs' bits as the C
    library's (atan2(0, -0.0) is pi).  In place of a call of libm's atan2 and acos per lane, which were half of
    the coordinates stage's time (decisions.md 48)."""
    b = v.b
    ay, ax = v.fabs(y), v.fabs(x)
    hi, lo = v.fmax(ay, ax), v.fmin(ay, ax)
    positive = v.gt(hi, v.f(0.0))
    t = b.select(positive, v.div(lo, b.select(positive, hi, v.f(1.0))), v.f(0.0))
    upper = v.gt(t, v.f(0.66))
    w = b.select(upper, v.div(v.sub(t, v.f(1.0)), v.add(t, v.f(1.0))), t)
    z = v.mul(w, w)
    p = v.f(_ATAN_P[0])
    for c in _ATAN_P[1:]:
        p = v.add(v.mul(p, z), v.f(c))
    q = v.add(z, v.f(_ATAN_Q[0]))
    for c in _ATAN_Q[1:]:
        q = v.add(v.mul(q, z), v.f(c))
    r = v.add(w, v.mul(w, v.div(v.mul(z, p), q)))
    r = b.select(upper, v.add(v.f(math.pi / 4), v.add(r, v.f(0.5 * _ATAN_MOREBITS))), r)
    r = b.select(v.gt(ay, ax), v.sub(v.f(math.pi / 2), r), r)
    r = b.select(_sign_bit(v, x), v.sub(v.f(math.pi), r), r)
    return b.select(_sign_bit(v, y), v.neg(r), r)


def _sign_bit(v: Lanes, x):
    """Which lanes have their sign bit set (-0.0 included: atan2(0, -0.0) is pi, as in the C library)."""
    return v.b.icmp_signed("<", v.b.bitcast(x, VI64), v.i(0))


def _acos_lanes(v: Lanes, c):
    """acos(c) for c in [-1, 1] as atan2(sqrt((1 - c)(1 + c)), c), within 2 ulp of the C library's."""
    return _atan2_lanes(v, v.sqrt(v.mul(v.sub(v.f(1.0), c), v.add(v.f(1.0), c))), c)


def _bucket(v: Lanes, u, buckets):
    """The guide bucket of a number in [0, 1): a dead lane's NaN or stale value included (clamped first, so that
    its index stays inside the table)."""
    bucket = v.b.fptosi(v.mul(v.clamp(u, 0.0, 1.0 - 2.0**-53), v.to_f(buckets)), VI64)
    return v.imin(bucket, v.b.sub(buckets, v.i(1)))


_SAMPLE_ARGS = (
    "env_u state material compensate m frame luminance sines plain_rows plain_marginal comp_rows comp_marginal "
    "plain_row_guide plain_marginal_guide comp_row_guide comp_marginal_guide "
    "comp_offset row_angles column_angles to_world wdir tpdf uv first count start"
).split()


#: dtype and dimensions of the array arguments both env_sample_block and env_coords_block take, the ones
#: _numbered_slots, _compensation and _node_weight read (every array C-contiguous)
_SHARED_DTYPES = {
    "state": (types.int8, 1),
    "material": (types.int64, 1),
    "compensate": (types.boolean, 1),
    "luminance": (types.float32, 2),
    "sines": (types.float64, 1),
    "plain_marginal": (types.float64, 1),
    "comp_marginal": (types.float64, 1),
    "wdir": (types.float64, 2),
    "uv": (types.float64, 2),
}
#: ... and those of env_sample_block's other array arguments
_SAMPLE_DTYPES = {
    **_SHARED_DTYPES,
    "env_u": (types.float64, 2),
    "frame": (types.float64, 2),
    "plain_rows": (types.float64, 2),
    "comp_rows": (types.float64, 2),
    "plain_row_guide": (types.int32, 2),
    "plain_marginal_guide": (types.int32, 1),
    "comp_row_guide": (types.int32, 2),
    "comp_marginal_guide": (types.int32, 1),
    "row_angles": (types.float64, 2),
    "column_angles": (types.float64, 2),
    "to_world": (types.float64, 2),
    "tpdf": (types.float64, 1),
}


@intrinsic
def env_sample_block(
    typingctx,
    env_u,
    state,
    material,
    compensate,
    m,
    frame,
    luminance,
    sines,
    plain_rows,
    plain_marginal,
    comp_rows,
    comp_marginal,
    plain_row_guide,
    plain_marginal_guide,
    comp_row_guide,
    comp_marginal_guide,
    comp_offset,
    row_angles,
    column_angles,
    to_world,
    wdir,
    tpdf,
    uv,
    first,
    count,
    start,
):
    """wavefront._env_sample_stage for environment slots ``start .. start + 7`` of a pass, numbered over its camera
    samples: slot ``first + q % count`` of camera sample ``q // count`` (its ``count`` environment samples begin
    at shading slot ``first``), so that all 8 lanes hold environment samples.  Each live one (state 2) gets the
    direction, density and lat-long coordinates of :func:`lightprobe.emitters.envmap.env_sample_full` for the
    bilinear density with the small-angle tables (``pdf="bilinear"``, maps of at least 64 node rows and 128
    columns), state 0 where the direction is below the shading point's surface or has no density.  Each lane runs
    the scalar code's operations in its order; the density (plain or compensated) is the slot's material's."""
    signature_args = (
        env_u, state, material, compensate, m, frame, luminance, sines, plain_rows, plain_marginal, comp_rows,
        comp_marginal, plain_row_guide, plain_marginal_guide, comp_row_guide, comp_marginal_guide, comp_offset,
        row_angles, column_angles, to_world, wdir, tpdf, uv, first, count, start,
    )  # fmt: skip
    if not _arguments_fit(_SAMPLE_ARGS, signature_args, _SAMPLE_DTYPES, floats=("comp_offset",)):
        return None

    def codegen(context, builder, signature, args):
        a = _Arguments(_SAMPLE_ARGS, context, builder, signature, args)
        v, b, arrays, shape = a.v, builder, a.arrays, a.shape
        k, slots, inside = _numbered_slots(a)
        _prefetch_ahead(
            a, (("state", 1, "slot", False), ("material", 8, "k", False), ("env_u", 16, "slot", False),
                ("frame", 72, "k", False), ("wdir", 24, "slot", True), ("uv", 16, "slot", True),
                ("tpdf", 8, "slot", True))
        )  # fmt: skip
        states = v.gather(I8, v.address(arrays["state"], slots, 1))
        live = b.and_(inside, b.icmp_signed("==", states, ir.Constant(VI8, [SLOT_LIGHT] * LANES)))
        skipped = v.skip_unless(live)
        compensated, offset = _compensation(a, k)
        u0 = v.load_f64(arrays["env_u"], b.mul(slots, v.i(2)))
        u1 = v.load_f64(arrays["env_u"], b.add(b.mul(slots, v.i(2)), v.i(1)))

        def pick(name_comp, name_plain):
            return _pick(a, compensated, name_comp, name_plain)

        rows_base, marginal_base = pick("comp_rows", "plain_rows"), pick("comp_marginal", "plain_marginal")
        ny, n1 = shape("plain_rows", 0), shape("plain_rows", 1)
        w = b.sub(n1, v.i(1))

        def marginal_at(index):
            return v.gather(F64, b.add(marginal_base, b.mul(index, v.i(8))))

        def rows_at(row, column):
            return v.gather(F64, b.add(rows_base, b.mul(b.add(b.mul(row, n1), column), v.i(8))))

        def guide_at(base, index):
            return b.sext(v.gather(I32, b.add(base, b.mul(index, v.i(4)))), VI64)

        def searched(lo, hi, top, below):
            """The bisection of [0, top] for the largest index that is ``below`` (envmap_bilinear's searches),
            started from the guide's bracket [lo, hi] where the bracket holds by the search's own compares (below
            at lo or lo = 0, not below at hi or hi = top): then it finds the same index.  Elsewhere -- a guide
            rounded the other way, both rows of a blend without weight -- from [0, top]."""
            lo_ok = b.or_(b.icmp_signed("==", lo, v.i(0)), below(v.imax(lo, v.i(0))))
            hi_ok = b.or_(b.icmp_signed("==", hi, top), b.not_(below(v.imin(v.imax(hi, v.i(0)), top))))
            ok = b.and_(b.and_(b.icmp_signed("<", lo, hi), b.icmp_signed(">=", lo, v.i(0))), b.and_(lo_ok, hi_ok))
            return v.bisect(b.select(ok, lo, v.i(0)), b.select(ok, hi, top), live, below)

        # envmap_bilinear.bilinear_sample, its two searches started from the guide tables' buckets (decisions.md 45)
        total = marginal_at(b.sub(ny, v.i(1)))
        one_minus_epsilon = v.f(1.0 - 2.0**-53)
        u1c = v.fmin(v.fmax(u1, v.f(0.0)), one_minus_epsilon)
        target = v.mul(u1c, total)
        buckets = b.sub(shape("plain_marginal_guide", 0), v.i(1))
        top = b.sub(ny, v.i(1))
        marginal_guide = pick("comp_marginal_guide", "plain_marginal_guide")
        bucket = _bucket(v, u1, buckets)
        lo = guide_at(marginal_guide, bucket)
        hi = v.imin(b.add(guide_at(marginal_guide, b.add(bucket, v.i(1))), v.i(1)), top)
        row = searched(lo, hi, top, lambda mid: v.le(marginal_at(mid), target))
        above = b.add(row, v.i(1))
        ra, rb = rows_at(row, w), rows_at(above, w)
        t = _invert_linear_lanes(v, ra, rb, v.sub(target, marginal_at(row)))
        s = v.sub(v.f(1.0), t)
        u0c = v.fmin(v.fmax(u0, v.f(0.0)), one_minus_epsilon)
        target_x = v.mul(u0c, v.add(v.mul(s, ra), v.mul(t, rb)))

        def column_below(mid):
            return v.le(v.add(v.mul(s, rows_at(row, mid)), v.mul(t, rows_at(above, mid))), target_x)

        # the blend of rows k and k + 1 crosses u0 of its total between the crossings of the two rows (its running
        # sums are a convex combination of theirs, normalised): the lower of the rows' bucket starts and the higher
        # of their bucket ends; a row without weight (-1) leaves the bracket to the other
        row_guide = pick("comp_row_guide", "plain_row_guide")
        guide_width = shape("plain_row_guide", 1)
        bucket = _bucket(v, u0, b.sub(guide_width, v.i(1)))
        starts = [guide_at(row_guide, b.add(b.mul(r, guide_width), bucket)) for r in (row, above)]
        starts = [b.select(b.icmp_signed("<", g, v.i(0)), w, g) for g in starts]
        ends = [guide_at(row_guide, b.add(b.mul(r, guide_width), b.add(bucket, v.i(1)))) for r in (row, above)]
        hi = v.imin(b.add(v.imax(ends[0], ends[1]), v.i(1)), w)
        column = searched(v.imin(starts[0], starts[1]), hi, w, column_below)
        width = shape("luminance", 1)
        node_weight = _node_weight(a, offset)
        right = b.add(column, v.i(1))
        c0 = v.add(v.mul(s, node_weight(row, column)), v.mul(t, node_weight(above, column)))
        c1 = v.add(v.mul(s, node_weight(row, right)), v.mul(t, node_weight(above, right)))
        base = v.add(v.mul(s, rows_at(row, column)), v.mul(t, rows_at(above, column)))
        tx = _invert_linear_lanes(v, c0, c1, v.sub(target_x, base))
        wf = v.to_f(w)
        x = v.div(v.add(v.to_f(column), tx), wf)
        x = b.select(v.ge(x, v.f(1.0)), one_minus_epsilon, x)
        ny1 = b.sub(ny, v.i(1))
        y = v.fmin(v.div(v.add(v.to_f(row), t), v.to_f(ny1)), v.f(1.0))
        joint = v.div(v.mul(v.add(v.mul(v.sub(v.f(1.0), tx), c0), v.mul(tx, c1)), v.to_f(b.mul(w, ny1))), total)
        # envmap.env_sample_full: the lookup's column centres, then the angles from the tables
        x = v.add(x, v.div(v.f(0.5), v.to_f(width)))
        x = b.select(v.ge(x, v.f(1.0)), v.sub(x, v.f(1.0)), x)
        angle_rows = shape("row_angles", 0)
        cd, sd = _small_cos_sin_lanes(v, v.div(v.mul(v.f(math.pi), t), v.to_f(b.sub(angle_rows, v.i(1)))))
        cos_row = v.load_f64(arrays["row_angles"], b.mul(row, v.i(2)))
        sin_row = v.load_f64(arrays["row_angles"], b.add(b.mul(row, v.i(2)), v.i(1)))
        cos_theta = v.sub(v.mul(cos_row, cd), v.mul(sin_row, sd))
        cd, sd = _small_cos_sin_lanes(v, v.div(v.mul(v.f(_TWO_PI), tx), v.to_f(shape("column_angles", 0))))
        ca = v.load_f64(arrays["column_angles"], b.mul(column, v.i(2)))
        sa = v.load_f64(arrays["column_angles"], b.add(b.mul(column, v.i(2)), v.i(1)))
        sin_phi = v.add(v.mul(sa, cd), v.mul(ca, sd))
        cos_phi = v.sub(v.mul(ca, cd), v.mul(sa, sd))
        sin_theta = v.sqrt(v.fmax(v.f(0.0), v.mul(v.sub(v.f(1.0), cos_theta), v.add(v.f(1.0), cos_theta))))
        local = (v.mul(sin_phi, sin_theta), cos_theta, v.mul(v.neg(cos_phi), sin_theta))
        matrix = arrays["to_world"]
        world = []
        for i in range(3):
            row_i = [b.load(b.gep(matrix.data, [I64(3 * i + j)])) for j in range(3)]
            terms = [v.mul(v.splat(row_i[j], VF64), local[j]) for j in range(3)]
            world.append(v.add(v.add(terms[0], terms[1]), terms[2]))
        pdf = b.select(v.le(sin_theta, v.f(0.0)), v.f(0.0), v.div(joint, v.mul(v.f(_TWO_PI_SQUARED), sin_theta)))
        # wavefront._env_sample_stage: below the shading point's surface, or no density: the slot is dropped
        normal = [v.load_f64(arrays["frame"], b.add(b.mul(k, v.i(9)), v.i(6 + i))) for i in range(3)]
        facing = v.add(v.add(v.mul(normal[0], world[0]), v.mul(normal[1], world[1])), v.mul(normal[2], world[2]))
        dropped = b.or_(v.le(facing, v.f(0.0)), v.le(pdf, v.f(0.0)))
        kept = b.and_(live, b.not_(dropped))
        v.store(I8, ir.Constant(VI8, [0] * LANES), v.address(arrays["state"], slots, 1), b.and_(live, dropped))
        for i in range(3):
            v.store(F64, world[i], b.add(v.address(arrays["wdir"], slots, 24), v.i(8 * i)), kept)
        v.store(F64, pdf, v.address(arrays["tpdf"], slots, 8), kept)
        v.store(F64, x, v.address(arrays["uv"], slots, 16), kept)
        v.store(F64, y, b.add(v.address(arrays["uv"], slots, 16), v.i(8)), kept)
        v.end_skip(skipped)
        return context.get_dummy_value()

    return types.void(*signature_args), codegen


# --- a direction's lat-long coordinates and the bilinear density there ------------------------------------------
_COORDS_ARGS = (
    "state material compensate m mis wdir to_env luminance sines plain_marginal comp_marginal comp_offset uv epdf "
    "first count start"
).split()
_COORDS_DTYPES = {**_SHARED_DTYPES, "to_env": (types.float64, 2), "epdf": (types.float64, 1)}
_INV_PI = 1.0 / math.pi  # sampling.kernels.INV_PI
_INV_2PI = 1.0 / (2.0 * math.pi)  # sampling.kernels.INV_2PI


@intrinsic
def env_coords_block(
    typingctx, state, material, compensate, m, mis, wdir, to_env, luminance, sines, plain_marginal, comp_marginal,
    comp_offset, uv, epdf, first, count, start,
):  # fmt: skip
    """wavefront._env_coords_stage for the slots ``start .. start + 7`` of a pass that are not environment samples,
    numbered over its camera samples as :func:`env_sample_block` numbers its own (slot ``first + q % count`` of
    camera sample ``q // count``): each live one gets the lat-long (u, v) of its direction (envmap.env_coords)
    and, under MIS, each BSDF sample the bilinear density there (envmap._pdf_at with ``pdf="bilinear"``).  atan2
    and acos are :func:`_atan2_lanes` and :func:`_acos_lanes`, within 2 ulp of the scalar stage's C library."""
    signature_args = (
        state, material, compensate, m, mis, wdir, to_env, luminance, sines, plain_marginal, comp_marginal,
        comp_offset, uv, epdf, first, count, start,
    )  # fmt: skip
    if not _arguments_fit(_COORDS_ARGS, signature_args, _COORDS_DTYPES, booleans=("mis",), floats=("comp_offset",)):
        return None

    def codegen(context, builder, signature, args):
        a = _Arguments(_COORDS_ARGS, context, builder, signature, args)
        v, b, arrays, shape = a.v, builder, a.arrays, a.shape
        k, read, inside = _numbered_slots(a)
        _prefetch_ahead(
            a, (("state", 1, "slot", False), ("material", 8, "k", False), ("wdir", 24, "slot", False),
                ("uv", 16, "slot", True), ("epdf", 8, "slot", True))
        )  # fmt: skip
        states = v.gather(I8, v.address(arrays["state"], read, 1))
        wanted = b.and_(inside, b.icmp_signed("!=", states, ir.Constant(VI8, [SLOT_NONE] * LANES)))
        wanted = b.and_(wanted, b.icmp_signed("!=", states, ir.Constant(VI8, [SLOT_LIGHT] * LANES)))
        skipped = v.skip_unless(wanted)
        # envmap.env_coords: the direction in the environment's frame, then mappings.direction_to_latlong
        world = [v.load_f64(arrays["wdir"], b.add(b.mul(read, v.i(3)), v.i(i))) for i in range(3)]
        local = []
        for i in range(3):
            row = [v.splat(b.load(b.gep(arrays["to_env"].data, [I64(3 * i + j)])), VF64) for j in range(3)]
            local.append(v.add(v.add(v.mul(row[0], world[0]), v.mul(row[1], world[1])), v.mul(row[2], world[2])))
        ex, ey, ez = local
        u = v.mul(_atan2_lanes(v, ex, v.neg(ez)), v.f(_INV_2PI))
        u = b.select(v.lt(u, v.f(0.0)), v.add(u, v.f(1.0)), u)
        u = b.select(v.ge(u, v.f(1.0)), v.f(0.0), u)
        lat = v.fmin(v.f(1.0), v.fmax(v.f(-1.0), ey))
        vv = v.mul(_acos_lanes(v, lat), v.f(_INV_PI))
        at = v.address(arrays["uv"], read, 16)
        v.store(F64, u, at, wanted)
        v.store(F64, vv, b.add(at, v.i(8)), wanted)
        # envmap._pdf_at for the bilinear density, at BSDF samples under MIS
        mis_v = v.splat(a.scalar("mis", types.boolean), MASK)
        bsdf = b.icmp_signed("==", states, ir.Constant(VI8, [SLOT_BSDF] * LANES))
        with_pdf = b.and_(b.and_(wanted, bsdf), mis_v)
        compensated, offset = _compensation(a, k)
        marginal_base = _pick(a, compensated, "comp_marginal", "plain_marginal")
        sin_theta = v.sqrt(v.fmax(v.f(0.0), v.mul(v.sub(v.f(1.0), ey), v.add(v.f(1.0), ey))))
        width = shape("luminance", 1)
        x = v.sub(u, v.div(v.f(0.5), v.to_f(width)))  # envmap._bilinear_x
        x = b.select(v.lt(x, v.f(0.0)), v.add(x, v.f(1.0)), x)
        # envmap_bilinear.bilinear_pdf; a coordinate outside [0, 1] (a NaN from a dead slot) has density 0, and is
        # clamped before it becomes an index
        ny = shape("sines", 0)
        inside_square = b.and_(
            b.and_(v.ge(x, v.f(0.0)), v.le(x, v.f(1.0))), b.and_(v.ge(vv, v.f(0.0)), v.le(vv, v.f(1.0)))
        )

        def cell(n, coordinate):  # envmap_bilinear._cell
            f = v.mul(v.fmin(v.fmax(v.clamp(coordinate, 0.0, 1.0), v.f(0.0)), v.f(1.0)), v.to_f(n))
            i = v.imin(b.fptosi(f, VI64), b.sub(n, v.i(1)))
            return i, v.sub(f, v.to_f(i))

        row, t = cell(b.sub(ny, v.i(1)), vv)
        column, tx = cell(width, x)

        node_weight = _node_weight(a, offset)
        s = v.sub(v.f(1.0), t)
        above, right = b.add(row, v.i(1)), b.add(column, v.i(1))
        c0 = v.add(v.mul(s, node_weight(row, column)), v.mul(t, node_weight(above, column)))
        c1 = v.add(v.mul(s, node_weight(row, right)), v.mul(t, node_weight(above, right)))
        total = v.gather(F64, b.add(marginal_base, b.mul(b.sub(ny, v.i(1)), v.i(8))))
        scale = v.to_f(b.mul(width, b.sub(ny, v.i(1))))
        p = v.div(v.mul(v.add(v.mul(v.sub(v.f(1.0), tx), c0), v.mul(tx, c1)), scale), total)
        p = b.select(inside_square, p, v.f(0.0))
        pdf = b.select(v.le(sin_theta, v.f(0.0)), v.f(0.0), v.div(p, v.mul(v.f(_TWO_PI_SQUARED), sin_theta)))
        v.store(F64, pdf, v.address(arrays["epdf"], read, 8), with_pdf)
        v.end_skip(skipped)
        return context.get_dummy_value()

    return types.void(*signature_args), codegen


# --- where the lanes apply ----------------------------------------------------------------------------------
@jit  # serial: it only checks the lanes once per process (a parallel loop compiles 0.2 s longer)
def _probe(radiance, image, uv, state):
    for block in range((state.shape[0] + LANES - 1) // LANES):
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


def coords_apply(k) -> bool:
    """Whether :func:`env_coords_block` fits environment kernel ``k``: the bilinear density, its tables
    C-contiguous float64 beside the float32 luminance, on a Numba that compiles the lanes."""
    from ...emitters.envmap import BILINEAR_PDF

    tables = (k.node_sines, k.marginal_cdf, k.comp_marginal_cdf, k.to_env)
    return (
        k.mode == BILINEAR_PDF
        and k.luminance.dtype == np.float32
        and k.luminance.flags.c_contiguous
        and all(t.flags.c_contiguous and t.dtype == np.float64 for t in tables)
        and compiles()
    )


def samples_apply(k) -> bool:
    """Whether :func:`env_sample_block` samples environment kernel ``k``: the bilinear density with the small-angle
    tables (maps of at least 64 node rows and 128 columns), on a Numba that compiles the lanes."""
    from ...emitters.envmap import BILINEAR_PDF
    from ...emitters.envmap_bilinear import SMALL_ANGLE_COLUMNS, SMALL_ANGLE_ROWS

    tables = (k.luminance, k.node_sines, k.conditional_cdf, k.marginal_cdf, k.comp_conditional_cdf)
    tables += (k.comp_marginal_cdf, k.row_angles, k.column_angles, k.to_world)
    guides = (k.marginal_guide, k.row_guide, k.comp_marginal_guide, k.comp_row_guide)
    return (
        k.mode == BILINEAR_PDF
        and k.row_angles.shape[0] >= SMALL_ANGLE_ROWS
        and k.column_angles.shape[0] >= SMALL_ANGLE_COLUMNS
        and k.luminance.dtype == np.float32
        and all(t.flags.c_contiguous for t in tables)
        and all(t.dtype == np.float64 for t in tables[1:])
        and all(g.dtype == np.int32 and g.flags.c_contiguous for g in guides)
        and k.row_guide.shape[1] == k.comp_row_guide.shape[1] == k.marginal_guide.shape[0]
        and k.marginal_guide.shape[0] == k.comp_marginal_guide.shape[0]
        and compiles()
    )
