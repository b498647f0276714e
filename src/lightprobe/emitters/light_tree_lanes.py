"""The light tree's importances of a node's eight children at once, as vector LLVM IR.

The light BVH's descent (``selection.select_light``, ``selection.selector_pmf``) weighs each child of a node by
pbrt-v4's ``LightBounds::Importance`` (``selection.node_importance``): four square roots and two divisions.  The
tree is eight-wide (``selection._collapse``): a node keeps its eight children's bounds field by field, eight numbers
side by side (row ``node`` of ``LightSelector.wide_bounds``: column ``f * 8 + c`` is field ``f`` of child ``c``), so
that :func:`child_importances` loads each field as one vector and computes the eight importances in the scalar
code's operations and order, lane by lane, in float32 once the receiver's offset from each centre is taken in
float64.  Float32 because the divider is the limit: on this project's Xeon a 512-bit square root of eight doubles
occupies it for about 24 cycles, 256 bits of eight floats for 6 (one node's eight importances: 44 -> 20 ns; a pick
on the 2,000-light scene 372 -> 267 ns; docs/decisions.md 90).  A pick and its pmf both come from these lanes, so
they agree; ``tests/emitters/test_light_tree_lanes.py`` bounds their difference from the float64 scalar code.
Numba's own vectorisers do not do this: LLVM's loop vectoriser leaves a loop of eight iterations alone, and Numba
runs LLVM without its SLP vectoriser (measured: the same loop in plain Numba, 16 scalar square roots).

An empty child (a node with fewer than eight) has power 0 and an emission cosine of 2: its importance is 0.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from ..geometry.wide_tree import WIDTH
from ..simd import F32, F64, I32, LANES, VF32, VF64, Lanes, Lanes32, array_structs, c_array, dot3, row_vector

__all__ = ["BOUNDS_WIDTH", "WIDTH", "child_importances"]

# a node's bounds, the fields of a row of LightSelector.node_bounds (and of each child in wide_bounds): centre of
# its box, half the box's diagonal (its bounding sphere's radius), axis of the normal cone, cos and sin of the
# cone's spread, cos of the emission spread about any normal, power, 1.0 if two-sided
B_CENTER, B_RADIUS, B_AXIS, B_COS_O, B_SIN_O, B_COS_E, B_PHI, B_TWO_SIDED = 0, 3, 4, 7, 8, 9, 10, 11
BOUNDS_WIDTH = 12


def _cos_sub_clamped(v: Lanes, sin_a, cos_a, sin_b, cos_b):
    """selection._cos_sub_clamped: cos(max(0, theta_a - theta_b))."""
    return v.b.select(v.gt(cos_a, cos_b), v.f(1.0), v.add(v.mul(cos_a, cos_b), v.mul(sin_a, sin_b)))


def _sin_sub_clamped(v: Lanes, sin_a, cos_a, sin_b, cos_b):
    return v.b.select(v.gt(cos_a, cos_b), v.f(0.0), v.sub(v.mul(sin_a, cos_b), v.mul(cos_a, sin_b)))


def importances(v: Lanes32, field, d, n, has_normal):
    """selection.node_importance for eight nodes whose bound fields are ``field(f)`` (float32 vectors), a receiver
    at ``d`` from their centres (float32 vectors, the differences taken in float64) with normal ``n`` (vectors of
    one value each); ``has_normal``: an i1, n is not 0."""
    b = v.b
    radius = field(B_RADIUS)
    d2 = dot3(v, d, d)
    dist = v.sqrt(d2)
    positive = v.gt(dist, v.f(0.0))
    inv_dist = b.select(positive, v.div(v.f(1.0), dist), v.f(0.0))
    falloff = v.div(v.f(1.0), v.fmax(d2, radius))
    along = dot3(v, [field(B_AXIS + i) for i in range(3)], d)
    along = b.select(b.fcmp_ordered("==", field(B_TWO_SIDED), v.f(1.0)), v.fabs(along), along)
    cos_w = v.mul(along, inv_dist)
    sin_w = v.mul(v.sqrt(v.fmax(v.f(0.0), v.sub(d2, v.mul(along, along)))), inv_dist)
    inside = v.le(dist, radius)
    sin_b = b.select(inside, v.f(0.0), v.mul(radius, inv_dist))
    cos_b = b.select(inside, v.f(-1.0), v.mul(v.sqrt(v.fmax(v.f(0.0), v.sub(d2, v.mul(radius, radius)))), inv_dist))
    cos_o, sin_o = field(B_COS_O), field(B_SIN_O)
    cos_x = _cos_sub_clamped(v, sin_w, cos_w, sin_o, cos_o)
    sin_x = _sin_sub_clamped(v, sin_w, cos_w, sin_o, cos_o)
    cos_p = _cos_sub_clamped(v, sin_x, cos_x, sin_b, cos_b)
    importance = v.mul(v.mul(field(B_PHI), cos_p), falloff)
    facing = v.fabs(dot3(v, n, d))
    cos_i = v.mul(facing, inv_dist)
    sin_i = v.mul(v.sqrt(v.fmax(v.f(0.0), v.sub(d2, v.mul(facing, facing)))), inv_dist)
    at_receiver = b.select(has_normal, _cos_sub_clamped(v, sin_i, cos_i, sin_b, cos_b), v.f(1.0))
    importance = b.select(has_normal, v.mul(importance, at_receiver), importance)
    return b.select(v.le(cos_p, field(B_COS_E)), v.f(0.0), v.fmax(importance, v.f(0.0)))


@intrinsic
def child_importances(typingctx, bounds, node, px, py, pz, nx, ny, nz):
    """The importances of the eight children of node ``node`` for a receiver at p with normal n (a tuple of eight
    floats); ``bounds`` is ``LightSelector.wide_bounds``, a C-contiguous float64 (M, BOUNDS_WIDTH * 8) array."""
    f64 = types.float64
    if not (
        c_array(bounds, f64, 2)
        and isinstance(node, types.Integer)
        and all(isinstance(t, types.Float) for t in (px, py, pz, nx, ny, nz))
    ):
        return None
    result = types.UniTuple(f64, LANES)

    def codegen(context, builder, signature, args):
        (bounds_a,) = array_structs(context, builder, signature, args, 1)
        v, b = Lanes(builder), builder
        node_i = context.cast(b, args[1], signature.args[1], types.int64)

        def loaded(f):
            return row_vector(v, bounds_a, node_i, BOUNDS_WIDTH * LANES, f * LANES)

        def field(f):
            return b.fptrunc(loaded(f), VF32)

        scalars = [context.cast(b, args[2 + i], signature.args[2 + i], f64) for i in range(6)]
        # the receiver from each centre in float64 (a scene far from the origin keeps its small lights' offsets),
        # then float32
        d = [b.fptrunc(v.sub(v.splat(scalars[i], VF64), loaded(B_CENTER + i)), VF32) for i in range(3)]
        n = [v.splat(b.fptrunc(x, F32), VF32) for x in scalars[3:]]
        zero = ir.Constant(F64, 0.0)
        has_normal = b.or_(
            b.or_(b.fcmp_unordered("!=", scalars[3], zero), b.fcmp_unordered("!=", scalars[4], zero)),
            b.fcmp_unordered("!=", scalars[5], zero),
        )
        out = b.fpext(importances(Lanes32(builder), field, d, n, has_normal), VF64)
        return context.make_tuple(b, result, [b.extract_element(out, I32(c)) for c in range(LANES)])

    return result(bounds, node, px, py, pz, nx, ny, nz), codegen
