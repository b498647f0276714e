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

from ..simd import I64, LANES, VF64, Lanes, array_structs, c_array, row_vector

__all__ = ["BOXES_WIDTH", "boxes_entered"]

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
        (boxes_a,) = array_structs(context, builder, signature, args, 1)
        v, b = Lanes(builder), builder
        node_i = context.cast(b, args[1], signature.args[1], types.int64)

        def corner(column):
            return row_vector(v, boxes_a, node_i, BOXES_WIDTH, column * LANES)

        o = [v.splat(context.cast(b, args[2 + a], signature.args[2 + a], f64), VF64) for a in range(3)]
        inv = [v.splat(context.cast(b, args[5 + a], signature.args[5 + a], f64), VF64) for a in range(3)]
        far_end = v.splat(context.cast(b, args[8], signature.args[8], f64), VF64)
        near, far = v.f(0.0), far_end
        for a in range(3):
            t_lo = v.mul(v.sub(corner(a), o[a]), inv[a])
            t_hi = v.mul(v.sub(corner(3 + a), o[a]), inv[a])
            near = v.fmax(near, v.fmin(t_lo, t_hi))
            far = v.fmin(far, v.fmax(t_lo, t_hi))
        present = b.fcmp_ordered("ord", corner(0), corner(0))  # a missing child's corners are NaN
        entered = b.and_(v.le(near, far), present)
        bits = b.bitcast(entered, ir.IntType(LANES))
        return b.zext(bits, I64)

    return types.int64(boxes, node, ox, oy, oz, ix, iy, iz, tmax), codegen
