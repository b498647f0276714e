"""Shadow rays against the analytic shapes, eight shading slots at a time, as vector LLVM IR.

``wavefront._shade_finish`` used to test each shadow ray against every sphere and rectangle (``occluded_analytic``)
and the meshes' bounding boxes (``may_hit_mesh``) one slot at a time, with early exits: 1.2 s of the peer scene's
12-s render at 64 spp, half of that stage (docs/decisions.md 49).  :func:`shadow_block` runs the same tests for 8
consecutive slots in 8 float64 lanes: the ray's origin (``intersect.ray_offset``), every sphere
(``intersect.sphere_hit``), every rectangle (``intersect.rect_hit``) and every box (``intersect.box_hit``) for the
unbounded ray, each without its early exits (a lane's answer does not depend on them: a slab interval once empty
stays empty), in the scalar code's operations and order.  A lane whose test is decided by a last-bit difference of
a fused multiply-add could differ from the scalar code's; the tests compare the two on random rays.

Each mesh also has two spheres (``geometry/proxies.py``, decisions.md 59): a ray through a closed mesh's inner ball
is ``BLOCKED`` and one that misses the sphere around a mesh does not reach it, so only rays between the two go to
Embree.  Lanes hold the slots whose flag is ``TEST_ANALYTIC`` (the finish stage's contributions, not yet tested);
each becomes ``BLOCKED``, ``TEST_MESH`` (for ``wavefront._mesh_shadow_stage``) or ``VISIBLE``.  Other slots and lanes
past the pass's end are not written.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ...geometry.intersect import RECT_WIDTH
from ...simd import F64, I8, I32, I64, LANES, VI8, Lanes, array_structs, c_array, dot3, ir_loop, splat_row
from ..techniques import BLOCKED, TEST_ANALYTIC, TEST_MESH, VISIBLE

__all__ = ["LANES", "shadow_block"]

_INF = float("inf")


def _toward_centre(v: Lanes, o, d, centre):
    """(f, bq, foot) of intersect.sphere_hit: the origin from the centre, the distance along the ray to the line's
    nearest point to the centre, and that point from the centre."""
    f = [v.sub(o[i], centre[i]) for i in range(3)]
    bq = v.neg(dot3(v, f, d))
    return f, bq, [v.add(f[i], v.mul(bq, d[i])) for i in range(3)]


def _sphere_t(v: Lanes, o, d, centre, radius, tmax):
    """intersect.sphere_hit(..., tmax): the nearest t in (0, tmax), else inf."""
    b = v.b
    f, bq, foot = _toward_centre(v, o, d, centre)
    r2 = v.mul(radius, radius)
    disc = v.sub(r2, dot3(v, foot, foot))
    c = v.sub(dot3(v, f, f), r2)
    s = v.sqrt(v.fmax(disc, v.f(0.0)))
    q = b.select(v.ge(bq, v.f(0.0)), v.add(bq, s), v.sub(bq, s))
    t0 = b.select(b.fcmp_unordered("!=", q, v.f(0.0)), v.div(c, q), v.f(_INF))
    t1 = q
    swap = v.gt(t0, t1)
    near, far = b.select(swap, t1, t0), b.select(swap, t0, t1)

    def within(t):
        return b.and_(v.gt(t, v.f(0.0)), v.lt(t, tmax))

    t = b.select(within(near), near, b.select(within(far), far, v.f(_INF)))
    return b.select(v.ge(disc, v.f(0.0)), t, v.f(_INF))


def _sphere_blocks(v: Lanes, o, d, centre, radius):
    """Whether ``_sphere_t(..., tmax=inf)`` is finite, without its square root and division: its roots are q and
    c / q, so one is positive exactly when q > 0, or q < 0 and c < 0 (c / q cannot underflow to 0: c is a difference
    of squares of order 1, q at most a scene's size); q = 0 gives no root in (0, inf) either way."""
    b = v.b
    f, bq, foot = _toward_centre(v, o, d, centre)
    r2 = v.mul(radius, radius)
    disc = v.sub(r2, dot3(v, foot, foot))
    c = v.sub(dot3(v, f, f), r2)
    # q = bq + s where bq >= 0, else bq - s (s = sqrt(max(disc, 0)) >= 0): q > 0 when bq > 0, or bq = 0 and s > 0;
    # q < 0 when bq < 0
    s_positive = v.gt(disc, v.f(0.0))
    q_positive = b.or_(v.gt(bq, v.f(0.0)), b.and_(b.fcmp_ordered("==", bq, v.f(0.0)), s_positive))
    q_negative = v.lt(bq, v.f(0.0))
    root = b.or_(q_positive, b.and_(q_negative, v.lt(c, v.f(0.0))))
    return b.and_(v.ge(disc, v.f(0.0)), root)


def _rect_t(v: Lanes, o, d, row, tmax):
    """intersect.rect_hit(..., tmax) for a row of intersect.rectangle_rows (origin, edges, normal, dual vectors) of
    splatted values: t, else inf."""
    b = v.b
    origin, normal, dual_u, dual_v = row[0:3], row[9:12], row[12:15], row[15:18]
    denom = dot3(v, d, normal)
    t = v.div(dot3(v, [v.sub(origin[i], o[i]) for i in range(3)], normal), denom)
    valid = b.and_(b.fcmp_unordered("!=", denom, v.f(0.0)), b.and_(v.gt(t, v.f(0.0)), v.lt(t, tmax)))
    p = [v.sub(v.add(o[i], v.mul(t, d[i])), origin[i]) for i in range(3)]  # intersect.rect_coordinates
    a = dot3(v, p, dual_u)
    c = dot3(v, p, dual_v)
    outside = b.or_(b.or_(v.lt(a, v.f(0.0)), v.gt(a, v.f(1.0))), b.or_(v.lt(c, v.f(0.0)), v.gt(c, v.f(1.0))))
    return b.select(b.and_(valid, b.not_(outside)), t, v.f(_INF))


def _box_hit(v: Lanes, o, d, lows, highs):
    """intersect.box_hit(..., tmax=inf) for a box's splatted corners: the three slabs without the early exits."""
    b = v.b
    t0, t1 = v.f(0.0), v.f(_INF)
    for axis in range(3):
        lo, hi = lows[axis], highs[axis]
        pad = v.mul(v.f(1e-6), v.add(v.add(v.fabs(lo), v.fabs(hi)), v.f(1.0)))
        lo_pad, hi_pad = v.sub(lo, pad), v.add(hi, pad)
        zero = b.fcmp_ordered("==", d[axis], v.f(0.0))
        outside = b.or_(v.lt(o[axis], lo_pad), v.gt(o[axis], hi_pad))
        inv = v.div(v.f(1.0), d[axis])
        a = v.mul(v.sub(lo_pad, o[axis]), inv)
        c = v.mul(v.sub(hi_pad, o[axis]), inv)
        swap = v.gt(a, c)
        a, c = b.select(swap, c, a), b.select(swap, a, c)
        n0, n1 = v.fmax(t0, a), v.fmin(t1, c)
        t0 = b.select(zero, b.select(outside, v.f(1.0), t0), n0)
        t1 = b.select(zero, b.select(outside, v.f(0.0), t1), n1)
    return v.le(t0, t1)


def _ball_crossed(v: Lanes, o, d, centre, radius2):
    """intersect.ball_crossed(..., tmax=inf) for a splatted centre and squared radius."""
    b = v.b
    f, bq, foot = _toward_centre(v, o, d, centre)
    near = v.gt(v.sub(radius2, dot3(v, foot, foot)), v.f(0.0))
    ahead = b.or_(v.lt(dot3(v, f, f), radius2), v.gt(bq, v.f(0.0)))
    return b.and_(near, ahead)


@intrinsic
def shadow_block(typingctx, flags, point, gnormal, point_error, wdir, spheres, rects, bounds, proxies, m, start):
    """For the slots ``start .. start + 7`` of a pass flagged TEST_ANALYTIC: the shadow ray from camera sample
    ``slot // m``'s point along the slot's direction, offset as ``ray_offset`` does, against every sphere and
    rectangle and every closed mesh's inner ball (BLOCKED if one is hit), then every mesh's box and the sphere
    around it (TEST_MESH if both of one mesh are crossed, else VISIBLE).  flags (N,) int8; point, gnormal (K, 3),
    point_error (K,), wdir (N, 3), spheres (S, 4), rects (R, RECT_WIDTH) float64; bounds (G, 2, 3) float64;
    proxies (G, 5) float64 (``SceneArrays.mesh_spheres``); all C-contiguous."""
    f64 = types.float64
    if not (
        c_array(flags, types.int8, 1)
        and all(c_array(t, f64, 2) for t in (point, gnormal, wdir, spheres, rects, proxies))
        and c_array(point_error, f64, 1)
        and c_array(bounds, f64, 3)
        and isinstance(m, types.Integer)
        and isinstance(start, types.Integer)
    ):
        return None

    def codegen(context, builder, signature, args):
        arrays = array_structs(context, builder, signature, args, 9)
        flags_a, point_a, normal_a, error_a, wdir_a, spheres_a, rects_a, bounds_a, proxies_a = arrays
        v, b = Lanes(builder), builder
        m_v = v.splat(context.cast(b, args[9], signature.args[9], types.int64), ir.VectorType(I64, LANES))
        start_v = context.cast(b, args[10], signature.args[10], types.int64)
        _, inside, read = v.slots(start_v, cgutils.unpack_tuple(b, flags_a.shape, 1)[0])
        first = b.extract_element(read, I32(0))
        states = v.load_run(I8, b.gep(flags_a.data, [first]), inside, 1, 0)
        live = b.and_(inside, b.icmp_signed("==", states, ir.Constant(VI8, [TEST_ANALYTIC] * LANES)))
        skipped = v.skip_unless(live)
        d = list(v.load_run(F64, b.gep(wdir_a.data, [b.mul(first, I64(3))]), inside, 3, 0.0))
        k = v.quotient(read, m_v)  # the camera sample of each slot
        p = [v.load_f64(point_a, b.add(b.mul(k, v.i(3)), v.i(i))) for i in range(3)]
        n = [v.load_f64(normal_a, b.add(b.mul(k, v.i(3)), v.i(i))) for i in range(3)]
        # intersect.ray_offset with the point's error bound
        eps = v.load_f64(error_a, k)
        facing = dot3(v, d, n)
        eps = b.select(v.lt(facing, v.f(0.0)), v.neg(eps), eps)
        o = [v.add(p[i], v.mul(eps, n[i])) for i in range(3)]

        none = ir.Constant(ir.VectorType(ir.IntType(1), LANES), [0] * LANES)
        counts = [cgutils.unpack_tuple(b, a.shape, nd)[0] for a, nd in ((spheres_a, 2), (rects_a, 2), (bounds_a, 3))]

        def sphere(i, blocked):
            row = splat_row(v, spheres_a, i, 4, range(4))
            return b.or_(blocked, _sphere_blocks(v, o, d, row[0:3], row[3]))

        def rect(i, blocked):
            row = splat_row(v, rects_a, i, RECT_WIDTH, range(RECT_WIDTH))
            return b.or_(blocked, v.lt(_rect_t(v, o, d, row, v.f(_INF)), v.f(_INF)))

        def mesh(i, carried):
            blocked, crossed = carried
            corners = splat_row(v, bounds_a, i, 6, range(6))
            proxy = splat_row(v, proxies_a, i, 5, range(5))
            around = b.and_(_box_hit(v, o, d, corners[0:3], corners[3:6]), _ball_crossed(v, o, d, proxy[0:3], proxy[3]))
            return b.or_(blocked, _ball_crossed(v, o, d, proxy[0:3], proxy[4])), b.or_(crossed, around)

        blocked = ir_loop(v, counts[0], none, sphere)
        blocked = ir_loop(v, counts[1], blocked, rect)
        blocked, crossed = ir_loop(v, counts[2], (blocked, none), mesh)
        result = b.select(
            blocked,
            ir.Constant(VI8, [BLOCKED] * LANES),
            b.select(crossed, ir.Constant(VI8, [TEST_MESH] * LANES), ir.Constant(VI8, [VISIBLE] * LANES)),
        )
        v.store(I8, result, v.address(flags_a, read, 1), live)
        v.end_skip(skipped)
        return context.get_dummy_value()

    return types.void(flags, point, gnormal, point_error, wdir, spheres, rects, bounds, proxies, m, start), codegen
