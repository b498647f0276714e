"""Which of a wide shape-tree node's eight boxes a ray segment enters, in one vector of eight lanes.

The shape hierarchy (``shape_bvh.py``) is walked eight children at a time (``intersect._first_hit``): row ``node`` of
``ShapeTree.boxes`` holds its children's boxes field by field (column ``a * 8 + c``: the low corner's axis a of child
c; ``24 + a * 8 + c``: the high corner's), so :func:`boxes_entered` loads each as one vector and runs
``shape_bvh.box_entered``'s slab test for the eight in its operations and order (``min`` and ``max`` as Numba's
builtins, left to right, so a NaN slab on a face drops out alike).  A missing child's box is NaN: no slab test
can exclude every segment from a box of infinite corners (at +inf, a ray whose direction is positive on every axis
enters it for tmax = inf), so those lanes are dropped by their NaN corner.  Returns the children entered as bits
0-7.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from ..simd import I64, LANES, MASK, VF64, VI64, Lanes, array_structs, c_array, llvm_function, row_vector

__all__ = ["BOXES_WIDTH", "boxes_entered", "nearest_boxes"]

BOXES_WIDTH = 6 * LANES  # columns of ShapeTree.boxes


@intrinsic
def boxes_entered(typingctx, boxes, node, ox, oy, oz, ix, iy, iz, tmax):
    """Bits 0-7: whether the segment [0, tmax] of the ray (o, 1/d = (ix, iy, iz)) meets child c's box of ``node``
    (``boxes``: a C-contiguous float64 (W, 48) array)."""
    f64 = types.float64
    if not (
        c_array(boxes, f64, 2)
        and isinstance(node, types.Integer)
        and all(isinstance(t, types.Float) for t in (ox, oy, oz, ix, iy, iz, tmax))
    ):
        return None

    def codegen(context, builder, signature, args):
        v, b = Lanes(builder), builder
        near, far, present = _slab_test(context, builder, signature, args)  # a missing child's corners are NaN
        entered = b.and_(v.le(near, far), present)
        bits = b.bitcast(entered, ir.IntType(LANES))
        return b.zext(bits, I64)

    return types.int64(boxes, node, ox, oy, oz, ix, iy, iz, tmax), codegen


def _slab_test(context, builder, signature, args):
    """(near, far, present) vectors of the slab test of ``node``'s eight child boxes (args: boxes, node, the
    origin, the reciprocal direction, tmax)."""
    f64 = types.float64
    (boxes_a,) = array_structs(context, builder, signature, args, 1)
    v, b = Lanes(builder), builder
    node_i = context.cast(b, args[1], signature.args[1], types.int64)

    def corner(column):
        return row_vector(v, boxes_a, node_i, BOXES_WIDTH, column * LANES)

    o = [v.splat(context.cast(b, args[2 + a], signature.args[2 + a], f64), VF64) for a in range(3)]
    inv = [v.splat(context.cast(b, args[5 + a], signature.args[5 + a], f64), VF64) for a in range(3)]
    near, far = v.f(0.0), v.splat(context.cast(b, args[8], signature.args[8], f64), VF64)
    for a in range(3):
        t_lo = v.mul(v.sub(corner(a), o[a]), inv[a])
        t_hi = v.mul(v.sub(corner(3 + a), o[a]), inv[a])
        near = v.fmax(near, v.fmin(t_lo, t_hi))
        far = v.fmin(far, v.fmax(t_lo, t_hi))
    return near, far, b.fcmp_ordered("ord", corner(0), corner(0))


@intrinsic
def nearest_boxes(typingctx, boxes, node, ox, oy, oz, ix, iy, iz, tmax, among, children):
    """Of the children in ``among`` (bits 0-7) whose boxes the segment [0, tmax] enters: bits 0-7, the one (or the
    ones, on a tie) whose box it enters first; bits 8-15, all of them; bits 16-23, those that are leaves (``children``:
    ShapeTree.child, (W, 8) int64, a leaf below -1).  The nearest-first walk of ``intersect._next_leaves``: with
    ``tmax`` the nearest hit so far, a child is tested again when the walk comes back to it, so one whose box lies
    beyond a hit found meanwhile is never entered."""
    f64 = types.float64
    if not (
        c_array(boxes, f64, 2)
        and isinstance(node, types.Integer)
        and all(isinstance(t, types.Float) for t in (ox, oy, oz, ix, iy, iz, tmax))
        and isinstance(among, types.Integer)
        and c_array(children, types.int64, 2)
    ):
        return None

    def codegen(context, builder, signature, args):
        v, b = Lanes(builder), builder
        near, far, present = _slab_test(context, builder, signature, args)
        wanted = context.cast(b, args[9], signature.args[9], types.int64)
        wanted = b.bitcast(b.trunc(wanted, ir.IntType(LANES)), MASK)
        entered = b.and_(b.and_(v.le(near, far), present), wanted)
        key = b.select(entered, near, v.f(float("inf")))
        least = b.call(llvm_function(b, f"llvm.vector.reduce.fmin.v{LANES}f64", VF64.element, VF64), [key])
        first = b.and_(b.fcmp_ordered("==", key, v.splat(least, VF64)), entered)
        kids = context.make_array(signature.args[10])(context, builder, args[10])
        node_i = context.cast(b, args[1], signature.args[1], types.int64)
        row = b.gep(kids.data, [b.mul(node_i, I64(LANES))])
        leaf = b.and_(b.icmp_signed("<", b.load(b.bitcast(row, VI64.as_pointer()), align=8), v.i(-1)), entered)

        def bits(mask, shift):
            return b.shl(b.zext(b.bitcast(mask, ir.IntType(LANES)), I64), I64(shift))

        return b.or_(b.or_(bits(first, 0), bits(entered, LANES)), bits(leaf, 2 * LANES))

    return types.int64(boxes, node, ox, oy, oz, ix, iy, iz, tmax, among, children), codegen
