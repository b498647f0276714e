"""Eight rays against the analytic shapes, as vector LLVM IR: the shape tests of the camera, BSDF and shadow rays.

A stage builds its rays with its scalar code, one slot at a time (a BSDF ray from its offset origin, a shadow ray to
infinity or to a point sampled on a light: ``shadows.shadow_ray``), into a per-thread block of :data:`FIELDS` x 8
numbers (``PassConstants.lane_rays``), and :func:`ray_block` tests the 8 against every shape in the scalar code's
operations and order (``intersect.closest_analytic``, ``may_hit_mesh``, ``blocked_by_mesh_core``).  So a ray's
construction has one source, the scalar one, and only the shape tests are written twice: here, for 8 float64 lanes
(``_sphere_t`` for ``intersect.sphere_hit``, ``_rect_t`` for ``rect_hit``, ``_box_hit`` for ``box_hit``,
``_ball_crossed`` for ``ball_crossed``), each without its early exits (a lane's answer does not depend on them: a
slab interval once empty stays empty).  In the shadow stage this replaced an intrinsic that built the environment's
shadow rays in the lanes as well, and was slower (decisions.md 101).

The block's rows: the input rays (origin, unit direction, ``tmax``: a lane with ``tmax`` <= 0 finds nothing), then
the answers: the nearest hit's distance in (0, ``tmax``) (``tmax`` if none, as ``closest_analytic``), its kind and
index (``MISS`` and -1 if none), whether a mesh's box and the sphere around it (``geometry/proxies.py``) are both
crossed before that distance (``may_hit_mesh``: Embree must look), and whether a closed mesh's inner ball is crossed
at all (``blocked_by_mesh_core``, for a ray to infinity).  Kinds, indices and the two answers are stored as float64
(small integers, exact).  A hit decided by a last-bit difference of a fused multiply-add could differ from the scalar
code's; the tests compare the two on random rays.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ..._numba import jit_inline
from ...geometry.intersect import MISS, RECT, RECT_WIDTH, SPHERE
from ...simd import F64, I64, LANES, VF64, Lanes, array_structs, c_array, dot3, ir_loop, splat_row

__all__ = [
    "CORE",
    "CROSSED",
    "DIRECTION",
    "FIELDS",
    "HIT_INDEX",
    "HIT_KIND",
    "HIT_T",
    "ORIGIN",
    "TMAX",
    "put_ray",
    "ray_block",
    "shape_tests",
]

# rows of a block (each LANES wide)
ORIGIN, DIRECTION, TMAX = 0, 3, 6  # in: origin x, y, z; unit direction x, y, z; the segment's end
HIT_T, HIT_KIND, HIT_INDEX, CROSSED, CORE = 7, 8, 9, 10, 11  # out
FIELDS = 12

_INF = float("inf")


@jit_inline
def put_ray(block, lane, ox, oy, oz, dx, dy, dz, tmax):
    """A stage's scalar code puts lane ``lane``'s ray into ``block`` (tmax <= 0: a lane that finds nothing)."""
    block[ORIGIN, lane], block[ORIGIN + 1, lane], block[ORIGIN + 2, lane] = ox, oy, oz
    block[DIRECTION, lane], block[DIRECTION + 1, lane], block[DIRECTION + 2, lane] = dx, dy, dz
    block[TMAX, lane] = tmax


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


def _box_hit(v: Lanes, o, d, lows, highs, tmax=None):
    """intersect.box_hit(..., tmax) for a box's splatted corners (tmax: lanes, or None for inf): the three slabs
    without the early exits."""
    b = v.b
    t0, t1 = v.f(0.0), v.f(_INF) if tmax is None else tmax
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


def _ball_crossed_before(v: Lanes, o, d, centre, radius2, tmax):
    """intersect.ball_crossed(..., tmax): the ball about ``centre`` of squared radius ``radius2`` (< 0: none) within
    the segment [0, tmax) -- the line passes inside it, and the origin is inside or the entry lies ahead before
    tmax."""
    b = v.b
    f, bq, foot = _toward_centre(v, o, d, centre)
    gap = v.sub(radius2, dot3(v, foot, foot))
    near = v.gt(gap, v.f(0.0))
    entry = v.sub(bq, v.sqrt(v.fmax(gap, v.f(0.0))))
    ahead = b.or_(v.lt(dot3(v, f, f), radius2), b.and_(v.gt(bq, v.f(0.0)), v.lt(entry, tmax)))
    return b.and_(near, ahead)


@intrinsic
def ray_block(typingctx, block, spheres, rects, bounds, proxies):
    """The answers of the module docstring for the 8 rays of ``block`` (FIELDS, 8) float64, C-contiguous, written to
    its answer rows.  spheres (S, 4), rects (R, RECT_WIDTH), proxies (G, 5) float64 (``SceneArrays.mesh_spheres``);
    bounds (G, 2, 3) float64; all C-contiguous."""
    f64 = types.float64
    if not (all(c_array(t, f64, 2) for t in (block, spheres, rects, proxies)) and c_array(bounds, f64, 3)):
        return None

    def codegen(context, builder, signature, args):
        block_a, spheres_a, rects_a, bounds_a, proxies_a = array_structs(context, builder, signature, args, 5)
        v, b = Lanes(builder), builder
        rows = b.bitcast(block_a.data, VF64.as_pointer())

        def row(i):
            return b.gep(rows, [I64(i)])

        o = [b.load(row(ORIGIN + i), align=8) for i in range(3)]
        d = [b.load(row(DIRECTION + i), align=8) for i in range(3)]
        tmax = b.load(row(TMAX), align=8)
        counts = [cgutils.unpack_tuple(b, a.shape, nd)[0] for a, nd in ((spheres_a, 2), (rects_a, 2), (bounds_a, 3))]

        def nearer(shape_kind, hit_at):
            """closest_analytic's loop body for one kind of shape: ``if t < best: best, kind, index = t, ...``."""

            def body(i, carried):
                best, kinds, indices = carried
                hit = hit_at(i, best)
                closer = v.lt(hit, best)
                index = v.b.sitofp(i, F64)
                return (
                    b.select(closer, hit, best),
                    b.select(closer, v.f(shape_kind), kinds),
                    b.select(closer, v.splat(index, VF64), indices),
                )

            return body

        def sphere(i, best):
            shape = splat_row(v, spheres_a, i, 4, range(4))
            return _sphere_t(v, o, d, shape[0:3], shape[3], best)

        def rect(i, best):
            return _rect_t(v, o, d, splat_row(v, rects_a, i, RECT_WIDTH, range(RECT_WIDTH)), best)

        none = ir.Constant(ir.VectorType(ir.IntType(1), LANES), [0] * LANES)

        def mesh(i, carried):
            crossed, core = carried
            corners = splat_row(v, bounds_a, i, 6, range(6))
            proxy = splat_row(v, proxies_a, i, 5, range(5))
            around = b.and_(
                _box_hit(v, o, d, corners[0:3], corners[3:6], best),
                _ball_crossed_before(v, o, d, proxy[0:3], proxy[3], best),
            )
            return b.or_(crossed, around), b.or_(core, _ball_crossed(v, o, d, proxy[0:3], proxy[4]))

        found = (tmax, v.f(MISS), v.f(-1))
        found = ir_loop(v, counts[0], found, nearer(SPHERE, sphere))
        best, kinds, indices = ir_loop(v, counts[1], found, nearer(RECT, rect))
        crossed, core = ir_loop(v, counts[2], (none, none), mesh)
        one, zero = v.f(1.0), v.f(0.0)
        for i, value in (
            (HIT_T, best),
            (HIT_KIND, kinds),
            (HIT_INDEX, indices),
            (CROSSED, b.select(crossed, one, zero)),
            (CORE, b.select(core, one, zero)),
        ):
            b.store(value, row(i), align=8)
        return context.get_dummy_value()

    return types.void(block, spheres, rects, bounds, proxies), codegen


@jit_inline
def shape_tests(block, count, spheres, rects, bounds, proxies):
    """``ray_block`` on a block whose first ``count`` lanes hold rays (``put_ray``); the other lanes get a ray that
    finds nothing."""
    for lane in range(count, LANES):
        put_ray(block, lane, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, -1.0)
    ray_block(block, spheres, rects, bounds, proxies)
