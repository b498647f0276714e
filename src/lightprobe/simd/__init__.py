"""The vector toolkit of lightprobe's hand-written stages: 8 lanes of LLVM IR, built with llvmlite inside Numba
``@intrinsic`` functions.

Numba compiles the renderer's stages one slot at a time: its loop vectoriser gives up on any loop that reads a table
(docs/decisions.md 35), so the stages that read tables per slot (the environment map's lookups and bisections, the
shadow and camera rays' shape tests, the Sobol' numbers) are written as intrinsics that emit the operation for 8
slots at once: :class:`Lanes` holds the operations, each as the scalar code's Python operator compiles (float
arithmetic with the kernels' fast-math flags, ``max``/``min`` as Numba's builtins), so a lane computes what the
scalar twin computes, operation for operation.  The intrinsics live beside the stages they serve (in
``integrators/stages/``: ``environment_lanes.py``, ``ray_lanes.py``, ``sobol_lanes.py``; and
``emitters/light_tree_lanes.py``, ``geometry/shape_tree_lanes.py``); each has a test that compares it with its twin.
The shape tests take rays that the stages' scalar code built (``ray_lanes``), so a ray has one source.

This package depends on nothing of lightprobe's: the constants an intrinsic needs (slot states, shadow flags) come
from the module that owns them.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils

__all__ = [
    "ELEMENTS",
    "F32",
    "F64",
    "FLAGS",
    "I8",
    "I32",
    "I64",
    "LANES",
    "MASK",
    "VF32",
    "VF64",
    "VI8",
    "VI32",
    "VI64",
    "Lanes",
    "Lanes32",
    "array_structs",
    "c_array",
    "dot3",
    "ir_loop",
    "llvm_function",
    "pointers",
    "row_vector",
    "splat_row",
]

LANES = 8

F32, F64, I8, I32, I64 = ir.FloatType(), ir.DoubleType(), ir.IntType(8), ir.IntType(32), ir.IntType(64)
VF64, VI64, VF32 = ir.VectorType(F64, LANES), ir.VectorType(I64, LANES), ir.VectorType(F32, LANES)
VI8, MASK = ir.VectorType(I8, LANES), ir.VectorType(ir.IntType(1), LANES)
VI32 = ir.VectorType(I32, LANES)
FLAGS = ("contract", "arcp", "afn")  # the scalar kernels' fast-math flags (_numba.FASTMATH)
#: (vector type, intrinsic suffix, alignment in bytes) of each element type stored here
ELEMENTS = {
    F32: (VF32, "v8f32", 4),
    F64: (VF64, "v8f64", 8),
    I8: (VI8, "v8i8", 1),
    I32: (VI32, "v8i32", 4),
    I64: (VI64, "v8i64", 8),
}


def llvm_function(builder, name: str, ret: ir.Type, *params: ir.Type):
    return cgutils.get_or_insert_function(builder.module, ir.FunctionType(ret, list(params)), name)


def pointers(element: ir.Type) -> ir.VectorType:
    return ir.VectorType(element.as_pointer(), LANES)


class Lanes:
    """The vector operations the intrinsics need, each as the scalar code's Python operator compiles: float
    arithmetic with the kernels' fast-math flags, ``max(a, b)`` as ``b if b > a else a`` and ``min(a, b)`` as
    ``b if b < a else a`` (Numba's builtins), integer arithmetic in int64."""

    def __init__(self, builder):
        self.b = builder

    def f(self, x):
        return ir.Constant(VF64, [float(x)] * LANES)

    def i(self, x):
        return ir.Constant(VI64, [int(x)] * LANES)

    def splat(self, value, t):
        lane0 = self.b.insert_element(ir.Constant(t, None), value, I32(0))
        return self.b.shuffle_vector(lane0, ir.Constant(t, None), ir.Constant(ir.VectorType(I32, LANES), [0] * 8))

    def add(self, a, c):
        return self.b.fadd(a, c, flags=FLAGS)

    def sub(self, a, c):
        return self.b.fsub(a, c, flags=FLAGS)

    def mul(self, a, c):
        return self.b.fmul(a, c, flags=FLAGS)

    def div(self, a, c):
        return self.b.fdiv(a, c, flags=FLAGS)

    def neg(self, a):
        return self.b.fneg(a, flags=FLAGS)

    def sqrt(self, a):
        return self.b.call(llvm_function(self.b, "llvm.sqrt.v8f64", VF64, VF64), [a], fastmath=FLAGS)

    def fabs(self, a):
        return self.b.call(llvm_function(self.b, "llvm.fabs.v8f64", VF64, VF64), [a])

    def fmax(self, a, c):
        return self.b.select(self.b.fcmp_ordered(">", c, a), c, a)

    def fmin(self, a, c):
        return self.b.select(self.b.fcmp_ordered("<", c, a), c, a)

    def imin(self, a, c):
        return self.b.select(self.b.icmp_signed("<", c, a), c, a)

    def imax(self, a, c):
        return self.b.select(self.b.icmp_signed(">", c, a), c, a)

    def lt(self, a, c):
        return self.b.fcmp_ordered("<", a, c)

    def le(self, a, c):
        return self.b.fcmp_ordered("<=", a, c)

    def gt(self, a, c):
        return self.b.fcmp_ordered(">", a, c)

    def ge(self, a, c):
        return self.b.fcmp_ordered(">=", a, c)

    def to_f(self, a):
        return self.b.sitofp(a, VF64)

    def quotient(self, a, c):
        """a // c for non-negative int64 lanes below 2^52 and c > 0, without an integer division (none in vector
        form): (a + 1/2) / c lies at least 1 / (2 c) from an integer, far above the rounding of a double."""
        return self.b.fptosi(self.div(self.add(self.to_f(a), self.f(0.5)), self.to_f(c)), VI64)

    def address(self, array, index, size):
        """Byte addresses of elements ``index`` (int64 lanes) of an array of ``size``-byte elements."""
        base = self.splat(self.b.ptrtoint(array.data, I64), VI64)
        return self.b.add(base, self.b.mul(index, self.i(size)))

    def gather(self, element, addresses):
        """The ``element`` values at 8 byte addresses (each must be valid), as 8 scalar loads: on AMD Zen 4 they
        beat ``vgatherqpd`` in the sampling stage's bisections, whose loads depend on the step before (peer scene,
        64 spp: 4.08 / 4.12 s against 4.61 / 5.03 s)."""
        out = ir.Constant(ELEMENTS[element][0], None)
        for lane in range(LANES):
            at = self.b.inttoptr(self.b.extract_element(addresses, I32(lane)), element.as_pointer())
            out = self.b.insert_element(out, self.b.load(at), I32(lane))
        return out

    def load_f64(self, array, index):
        return self.gather(F64, self.address(array, index, 8))

    def load_f32(self, array, index):
        return self.b.fpext(self.gather(F32, self.address(array, index, 4)), VF64)

    def store(self, element, values, addresses, mask):
        """A masked scatter: the lanes where ``mask`` is false write nothing."""
        vector, suffix, align = ELEMENTS[element]
        function = llvm_function(
            self.b, f"llvm.masked.scatter.{suffix}.v{LANES}p0", ir.VoidType(), vector, pointers(element), I32, MASK
        )
        self.b.call(function, [values, self.b.inttoptr(addresses, pointers(element)), I32(align), mask])

    def load_run(self, element, pointer, mask, fields, fill):
        """Lanes 0-7 of ``fields`` interleaved values from ``pointer`` on (8 rows of a (N, fields) array, or of a
        vector when fields is 1), by one masked load: rows whose lane is off are not read and get ``fill``.
        Returns one vector per field."""
        b = self.b
        _, suffix, align = ELEMENTS[element]
        width = fields * LANES
        wide = ir.VectorType(element, width)
        wide_mask = self._widen(mask, fields)
        constant = float(fill) if element in (F32, F64) else int(fill)
        function = llvm_function(
            b, f"llvm.masked.load.v{width}{suffix[2:]}.p0", wide, wide.as_pointer(), I32, wide_mask.type, wide
        )
        values = b.call(function, [b.bitcast(pointer, wide.as_pointer()), I32(align), wide_mask,
                                   ir.Constant(wide, [constant] * width)])  # fmt: skip
        if fields == 1:
            return values
        indices = ir.VectorType(I32, LANES)
        return tuple(
            b.shuffle_vector(values, values, ir.Constant(indices, [fields * lane + f for lane in range(LANES)]))
            for f in range(fields)
        )

    def store_run(self, vectors, pointer, mask):
        """The inverse of :meth:`load_run` for float64 fields: row i gets lane i of each vector where ``mask``."""
        b = self.b
        fields = len(vectors)
        width = fields * LANES
        wide = ir.VectorType(F64, width)
        parts = list(vectors)
        while len(parts) > 1:  # concatenate the fields (an odd one out padded with undefined lanes)
            if len(parts) % 2:
                parts.append(ir.Constant(parts[0].type, None))
            n = parts[0].type.count
            join = ir.Constant(ir.VectorType(I32, 2 * n), list(range(2 * n)))
            parts = [b.shuffle_vector(parts[i], parts[i + 1], join) for i in range(0, len(parts), 2)]
        order = [f * LANES + lane for lane in range(LANES) for f in range(fields)]  # then interleave them
        values = b.shuffle_vector(parts[0], parts[0], ir.Constant(ir.VectorType(I32, width), order))
        wide_mask = self._widen(mask, fields)
        function = llvm_function(
            b, f"llvm.masked.store.v{width}f64.p0", ir.VoidType(), wide, wide.as_pointer(), I32, wide_mask.type
        )
        target = b.bitcast(pointer, wide.as_pointer())
        # every lane live (the usual block): a plain store, which a later scalar load of one of its values can take
        # from the store buffer; a load after a masked store waits until the store has reached the cache (perf: the
        # setup stage's reads of the Sobol' rows just stored, decisions.md 64)
        full = b.call(llvm_function(b, f"llvm.vector.reduce.and.v{LANES}i1", ir.IntType(1), MASK), [mask])
        with b.if_else(full) as (every_lane, some_lanes):
            with every_lane:
                b.store(values, target, align=8)
            with some_lanes:
                b.call(function, [values, target, I32(8), wide_mask])

    def _widen(self, mask, fields):
        """Each lane's mask bit repeated ``fields`` times, in row order."""
        if fields == 1:
            return mask
        order = [lane for lane in range(LANES) for _ in range(fields)]
        return self.b.shuffle_vector(mask, mask, ir.Constant(ir.VectorType(I32, fields * LANES), order))

    def clamp(self, x, lo, hi):
        """x clipped to [lo, hi], a NaN to lo (both compares are false for it)."""
        x = self.b.select(self.ge(x, self.f(lo)), x, self.f(lo))
        return self.b.select(self.le(x, self.f(hi)), x, self.f(hi))

    def slots(self, start, n):
        """(slot indices start .. start + 7, which of them are below n, the indices clipped to n - 1 for reading)."""
        slots = self.b.add(self.splat(start, VI64), ir.Constant(VI64, list(range(LANES))))
        n = self.splat(n, VI64)
        return slots, self.b.icmp_signed("<", slots, n), self.imin(slots, self.b.sub(n, self.i(1)))

    def any(self, mask):
        reduce = llvm_function(self.b, f"llvm.vector.reduce.or.v{LANES}i1", ir.IntType(1), MASK)
        return self.b.call(reduce, [mask])

    def skip_unless(self, mask):
        """Branch past the code that follows, up to :meth:`end_skip`, when no lane of ``mask`` is set (a block
        whose slots are all dead -- a sky pixel's -- writes nothing, so it need not compute anything either)."""
        work = self.b.append_basic_block("block.live")
        done = self.b.append_basic_block("block.done")
        self.b.cbranch(self.any(mask), work, done)
        self.b.position_at_end(work)
        return done

    def end_skip(self, done):
        self.b.branch(done)
        self.b.position_at_end(done)

    def bisect(self, lo, hi, mask, below):
        """Per lane of ``mask``, envmap_bilinear's bisection: while hi - lo > 1, mid = (lo + hi) >> 1 becomes lo
        where ``below(mid)`` (the value at mid <= the target) and hi elsewhere.  Lanes stop one by one; the loop runs
        while any lane is active.  Returns lo."""
        b = self.b
        entry = b.block
        loop = b.append_basic_block("bisect")
        body = b.append_basic_block("bisect.step")
        done = b.append_basic_block("bisect.done")
        b.branch(loop)
        b.position_at_end(loop)
        lo_phi, hi_phi = b.phi(VI64), b.phi(VI64)
        lo_phi.add_incoming(lo, entry)
        hi_phi.add_incoming(hi, entry)
        active = b.and_(mask, b.icmp_signed(">", b.sub(hi_phi, lo_phi), self.i(1)))
        b.cbranch(self.any(active), body, done)
        b.position_at_end(body)
        mid = b.ashr(b.add(lo_phi, hi_phi), self.i(1))
        up = below(mid)
        go_up = b.and_(active, up)
        go_down = b.and_(active, b.not_(up))
        lo_phi.add_incoming(b.select(go_up, mid, lo_phi), b.block)
        hi_phi.add_incoming(b.select(go_down, mid, hi_phi), b.block)
        b.branch(loop)
        b.position_at_end(done)
        return lo_phi


class Lanes32(Lanes):
    """:class:`Lanes` over eight float32 lanes (one 256-bit register): constants, square root and absolute value in
    float32; the other operations take their operands' type."""

    def f(self, x):
        return ir.Constant(VF32, [float(x)] * LANES)

    def sqrt(self, a):
        return self.b.call(llvm_function(self.b, "llvm.sqrt.v8f32", VF32, VF32), [a], fastmath=FLAGS)

    def fabs(self, a):
        return self.b.call(llvm_function(self.b, "llvm.fabs.v8f32", VF32, VF32), [a])


def ir_loop(v: Lanes, count, carried, body):
    """``for i in range(count): carried = body(i, carried)`` as an IR loop (``count`` an i64 scalar, ``carried`` a
    value, or a tuple of values, threaded through the iterations); returns the last ``carried``."""
    b = v.b
    single = not isinstance(carried, tuple)
    values = (carried,) if single else carried
    entry = b.block
    head = b.append_basic_block("shapes")
    done = b.append_basic_block("shapes.done")
    b.cbranch(b.icmp_signed(">", count, I64(0)), head, done)
    b.position_at_end(head)
    i = b.phi(I64)
    phis = [b.phi(x.type) for x in values]
    i.add_incoming(I64(0), entry)
    for phi, x in zip(phis, values, strict=True):
        phi.add_incoming(x, entry)
    new_values = body(i, phis[0] if single else tuple(phis))
    new_values = (new_values,) if single else new_values
    following = b.add(i, I64(1))
    latch = b.block
    i.add_incoming(following, latch)
    for phi, x in zip(phis, new_values, strict=True):
        phi.add_incoming(x, latch)
    b.cbranch(b.icmp_signed("<", following, count), head, done)
    b.position_at_end(done)
    results = []
    for x, y in zip(values, new_values, strict=True):
        result = b.phi(x.type)
        result.add_incoming(x, entry)
        result.add_incoming(y, latch)
        results.append(result)
    return results[0] if single else tuple(results)


def c_array(t, dtype, ndim) -> bool:
    """Whether an intrinsic's argument type is a C-contiguous array of ``dtype`` and ``ndim``."""
    return isinstance(t, types.Array) and t.dtype == dtype and t.ndim == ndim and t.layout == "C"


def array_structs(context, builder, signature, args, n):
    """The intrinsic's first ``n`` arguments (arrays) as Numba array structures."""
    return [
        context.make_array(t)(context, builder, value) for t, value in zip(signature.args[:n], args[:n], strict=True)
    ]


def splat_row(v: Lanes, array, i, width, fields):
    """Elements ``fields`` of row i of a C-contiguous float64 (N, width) array, each splatted to the lanes."""
    base = v.b.mul(i, I64(width))
    return [v.splat(v.b.load(v.b.gep(array.data, [v.b.add(base, I64(f))])), VF64) for f in fields]


def row_vector(v: Lanes, array, i, width, column):
    """Elements ``column`` .. ``column`` + 7 of row i of a C-contiguous float64 (N, width) array, as one vector: a
    field of eight children stored side by side (the wide trees' rows)."""
    at = v.b.gep(array.data, [v.b.add(v.b.mul(i, I64(width)), I64(column))])
    return v.b.load(v.b.bitcast(at, VF64.as_pointer()), align=8)


def dot3(v: Lanes, x, y):
    """x . y of 3-vectors of lanes, summed as the scalar code writes it: (x0 y0 + x1 y1) + x2 y2."""
    return v.add(v.add(v.mul(x[0], y[0]), v.mul(x[1], y[1])), v.mul(x[2], y[2]))
