"""Camera rays' nearest analytic hits, eight camera samples at a time, as vector LLVM IR.

``wavefront._camera_pass`` found each camera ray's nearest sphere or rectangle with ``intersect.closest_analytic``,
one ray at a time: about half of that stage on the peer scene (1.09 -> 0.58 s at 64 spp with a stand-in,
docs/decisions.md 49, 50).  :func:`nearest_block` runs the same search for 8 consecutive camera samples in 8 float64
lanes: every sphere (``intersect.sphere_hit``), then every rectangle (``intersect.rect_hit``), each tested up to the
nearest hit so far, in the scalar code's operations and order (the shape tests are those of
:mod:`lightprobe.geometry.shadow_lanes`).  A hit decided by a last-bit difference of a fused multiply-add could
differ from the scalar code's; the tests compare the two on random rays.

The meshes stay with the caller, in the same loop (decisions.md 30: camera rays are coherent).
"""

from __future__ import annotations

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ...geometry.intersect import MISS, RECT, RECT_WIDTH, SPHERE
from ...simd import F64, I32, I64, LANES, VF64, VI64, Lanes, array_structs, c_array, ir_loop, splat_row
from .shadow_lanes import _INF, _rect_t, _sphere_t

__all__ = ["LANES", "nearest_block"]


@intrinsic
def nearest_block(typingctx, dirs, t, kind, index, cam, spheres, rects, start):
    """For camera samples ``start .. start + 7`` (those below ``len(dirs)``): (t, kind, index) of
    ``intersect.closest_analytic`` from the camera's origin ``cam[0:3]`` along ``dirs[k]`` with no bound: MISS, -1
    and inf where no sphere or rectangle is hit.  dirs (N, 3), t (N,), cam (>= 3,), spheres (S, 4),
    rects (R, RECT_WIDTH) float64; kind, index (N,) int64; all C-contiguous."""
    f64, i64 = types.float64, types.int64
    if not (
        all(c_array(a, f64, 2) for a in (dirs, spheres, rects))
        and c_array(t, f64, 1)
        and c_array(cam, f64, 1)
        and c_array(kind, i64, 1)
        and c_array(index, i64, 1)
        and isinstance(start, types.Integer)
    ):
        return None

    def codegen(context, builder, signature, args):
        dirs_a, t_a, kind_a, index_a, cam_a, spheres_a, rects_a = array_structs(context, builder, signature, args, 7)
        v, b = Lanes(builder), builder
        start_v = context.cast(b, args[7], signature.args[7], types.int64)
        _, inside, read = v.slots(start_v, cgutils.unpack_tuple(b, t_a.shape, 1)[0])
        first = b.extract_element(read, I32(0))
        d = list(v.load_run(F64, b.gep(dirs_a.data, [b.mul(first, I64(3))]), inside, 3, 0.0))
        o = [v.splat(b.load(b.gep(cam_a.data, [I64(i)])), VF64) for i in range(3)]
        counts = [cgutils.unpack_tuple(b, a.shape, 2)[0] for a in (spheres_a, rects_a)]

        def nearer(shape_kind, hit_at):
            """closest_analytic's loop body for one kind of shape: ``if t < best: best, kind, index = t, ...``,
            t = hit_at(i, best)."""

            def body(i, carried):
                best, kinds, indices = carried
                hit = hit_at(i, best)
                closer = v.lt(hit, best)
                return (
                    b.select(closer, hit, best),
                    b.select(closer, v.i(shape_kind), kinds),
                    b.select(closer, v.splat(i, VI64), indices),
                )

            return body

        def sphere(i, best):
            row = splat_row(v, spheres_a, i, 4, range(4))
            return _sphere_t(v, o, d, row[0:3], row[3], best)

        def rect(i, best):
            return _rect_t(v, o, d, splat_row(v, rects_a, i, RECT_WIDTH, range(RECT_WIDTH)), best)

        found = (v.f(_INF), v.i(MISS), v.i(-1))
        found = ir_loop(v, counts[0], found, nearer(SPHERE, sphere))
        best, kinds, indices = ir_loop(v, counts[1], found, nearer(RECT, rect))
        v.store_run([best], b.gep(t_a.data, [first]), inside)
        for array, values in ((kind_a, kinds), (index_a, indices)):  # int64 lanes stored as their bits
            v.store_run([b.bitcast(values, VF64)], b.gep(array.data, [first]), inside)
        return context.get_dummy_value()

    return types.void(dirs, t, kind, index, cam, spheres, rects, start), codegen
