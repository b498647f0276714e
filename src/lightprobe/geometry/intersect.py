"""Ray-shape intersection kernels for the analytic shapes, bounding-box culling, and surface reconstruction.

Meshes are intersected by Embree (:mod:`lightprobe.geometry.raytracer`); spheres and rectangles exactly here, in
double precision.  Before a ray goes to Embree its segment is tested against every mesh's bounding box, so rays
that cannot reach a mesh (most shadow rays from a ground plane toward the sky, for instance) never leave Numba.

Hit kinds: ``MISS`` (0), ``MESH`` (1), ``SPHERE`` (2), ``RECT`` (3).

Rectangles are parallelograms: a row of ``RECT_WIDTH`` numbers (:func:`rectangle_rows`) holds the corner, the two
edges, the unit normal and the edges' *dual* vectors, so that a point's coordinates in the oblique edge basis are
two dot products (``rect_hit``; the same row layout serves the light table, ``emitters/area.py``).

Rays leave a surface from an origin moved along the geometric normal by the hit point's error bound
(:func:`ray_offset`; pbrt-v4's ``OffsetRayOrigin`` with the point's floating-point error, Physically Based Rendering
4th ed. 6.8.6): a bound in each coordinate, weighted by the normal's components, so that a horizontal ground
1000 units from the origin moves its rays by the error of its height, not of its x coordinate.  Mesh points are
traced by Embree in float32, analytic shapes here in float64: their bounds differ by nine orders of magnitude.
"""

from __future__ import annotations

import math

import numpy as np
from numba.cpython.unsafe.numbers import trailing_zeros

from .._numba import jit, jit_inline
from .frame import normalize
from .shape_tree_lanes import boxes_entered, nearest_boxes

__all__ = [
    "ANALYTIC_ERROR",
    "MESH",
    "MESH_ERROR",
    "MISS",
    "RECT",
    "RECT_WIDTH",
    "SPHERE",
    "closest_analytic",
    "occluded_analytic",
    "point_error",
    "ray_offset",
    "rect_hit",
    "rectangle_rows",
    "rectangle_rows_of",
    "surface",
    "triangle_error",
]

MISS, MESH, SPHERE, RECT = 0, 1, 2, 3
INF = math.inf
RECT_WIDTH = 18  # a rectangle's row: corner 0-2, edge u 3-5, edge v 6-8, unit normal 9-11, dual u 12-14, dual v 15-17
# Error bounds of hit points, relative to the magnitudes of the coordinates they come from (the distance a spawned
# ray's origin moves along the normal, see ray_offset).  Meshes: Embree holds vertices and ray origins in float32
# (half an ulp each, 2^-24 relative) and its Pluecker test subtracts the origin from the vertices (errors of the
# triangle's size times 2^-24); 2^-20 is 8-16 float32 ulps, a margin of 4-8 over those sums (measured in
# tests/geometry/test_offsets.py: self-hits start between a quarter and a sixteenth of it).  Analytic shapes:
# float64 throughout (points projected back onto their surface), 2^-40 = 4096 float64 ulps.
MESH_ERROR = 2.0**-20
ANALYTIC_ERROR = 2.0**-40


def rectangle_rows(origin, edge_u, edge_v):
    """Rows (R, RECT_WIDTH) of parallelograms given their corners and edges (R, 3) each: the normal
    normalize(u x v) and the dual vectors u* = (v x n) / |u x v|, v* = (n x u) / |u x v|, which give a point
    p = a u + b v of the plane its coordinates a = p . u*, b = p . v* (u* . u = 1, u* . v = 0, and so on)."""
    o, u, v = (np.asarray(x, dtype=np.float64).reshape(-1, 3) for x in (origin, edge_u, edge_v))
    cross = np.cross(u, v)
    area = np.linalg.norm(cross, axis=1, keepdims=True)
    n = cross / area
    return np.ascontiguousarray(np.concatenate([o, u, v, n, np.cross(v, n) / area, np.cross(n, u) / area], axis=1))


def rectangle_rows_of(rects) -> np.ndarray:
    """:func:`rectangle_rows` of shapes with ``origin``, ``edge_u`` and ``edge_v`` (geometry.shapes.Rectangle)."""
    if not rects:
        return np.zeros((0, RECT_WIDTH))
    return rectangle_rows(*(np.array([getattr(r, f) for r in rects]) for f in ("origin", "edge_u", "edge_v")))


@jit
def sphere_hit(ox, oy, oz, dx, dy, dz, cx, cy, cz, r, tmax):
    """Nearest t in (0, tmax) of a unit-direction ray with a sphere, or inf.  Numerically robust form
    (Haines et al., Ray Tracing Gems ch. 7): the discriminant from the distance of the centre to the line."""
    fx, fy, fz = ox - cx, oy - cy, oz - cz
    b = -(fx * dx + fy * dy + fz * dz)
    qx, qy, qz = fx + b * dx, fy + b * dy, fz + b * dz
    disc = r * r - (qx * qx + qy * qy + qz * qz)
    if disc < 0.0:
        return INF
    c = fx * fx + fy * fy + fz * fz - r * r
    s = math.sqrt(disc)
    q = b + s if b >= 0.0 else b - s
    t0 = c / q if q != 0.0 else INF
    t1 = q
    if t0 > t1:
        t0, t1 = t1, t0
    if 0.0 < t0 < tmax:
        return t0
    if 0.0 < t1 < tmax:
        return t1
    return INF


@jit_inline
def rect_coordinates(rects, i, px, py, pz):
    """(a, b) with p = corner + a edge_u + b edge_v for a point p in the plane of parallelogram i of ``rects``
    (rows of :func:`rectangle_rows`): the offset from the corner against the dual vectors."""
    qx, qy, qz = px - rects[i, 0], py - rects[i, 1], pz - rects[i, 2]
    a = qx * rects[i, 12] + qy * rects[i, 13] + qz * rects[i, 14]
    b = qx * rects[i, 15] + qy * rects[i, 16] + qz * rects[i, 17]
    return a, b


@jit_inline
def rect_hit(ox, oy, oz, dx, dy, dz, rects, i, tmax):
    """Distance to parallelogram i of ``rects`` (rows of :func:`rectangle_rows`), INF if missed before tmax.  The
    single routine for every caller: camera, shadow and BSDF rays, the light table (``emitters/area.py``), and the
    vector lanes' ``_rect_t`` (integrators/stages/ray_lanes.py) in the same operations."""
    nx, ny, nz = rects[i, 9], rects[i, 10], rects[i, 11]
    denom = dx * nx + dy * ny + dz * nz
    if denom == 0.0:
        return INF
    t = ((rects[i, 0] - ox) * nx + (rects[i, 1] - oy) * ny + (rects[i, 2] - oz) * nz) / denom
    if not (0.0 < t < tmax):
        return INF
    a, b = rect_coordinates(rects, i, ox + t * dx, oy + t * dy, oz + t * dz)
    if a < 0.0 or a > 1.0 or b < 0.0 or b > 1.0:
        return INF
    return t


@jit_inline
def _slab(o, d, lo, hi, t0, t1):
    """One axis of the slab test: the interval (t0, t1) clipped to the slab [lo, hi] (inflated a little)."""
    pad = 1e-6 * (abs(lo) + abs(hi) + 1.0)
    if d == 0.0:
        if o < lo - pad or o > hi + pad:
            return 1.0, 0.0  # empty
        return t0, t1
    inv = 1.0 / d
    a = (lo - pad - o) * inv
    b = (hi + pad - o) * inv
    if a > b:
        a, b = b, a
    return max(t0, a), min(t1, b)


@jit_inline
def box_hit(ox, oy, oz, dx, dy, dz, bounds, g, tmax):
    """Does the segment (0, tmax) cross box g of ``bounds`` (G, 2, 3)?  (Slab test, with a small inflation for
    safety.)  Reads scalars: slicing the box out as an array view costs a reference-count update on the shared
    parent array, which two threads contend for (measured: 140 ns per test, 10x the arithmetic)."""
    t0, t1 = _slab(ox, dx, bounds[g, 0, 0], bounds[g, 1, 0], 0.0, tmax)
    if t0 > t1:
        return False
    t0, t1 = _slab(oy, dy, bounds[g, 0, 1], bounds[g, 1, 1], t0, t1)
    if t0 > t1:
        return False
    t0, t1 = _slab(oz, dz, bounds[g, 0, 2], bounds[g, 1, 2], t0, t1)
    return t0 <= t1


@jit_inline
def _shape_t(s, p, ox, oy, oz, dx, dy, dz, tmax):
    """Distance to analytic shape p (p < S: sphere p, else rectangle p - S), INF if missed before tmax."""
    n_spheres = s.spheres.shape[0]
    if p < n_spheres:
        return sphere_hit(
            ox, oy, oz, dx, dy, dz, s.spheres[p, 0], s.spheres[p, 1], s.spheres[p, 2], s.spheres[p, 3], tmax
        )
    return rect_hit(ox, oy, oz, dx, dy, dz, s.rects, p - n_spheres, tmax)


@jit_inline
def _reciprocal(d):
    """1 / d for the slab tests, a huge finite number for d = 0 (no 0 x inf = NaN on a box face)."""
    return 1.0 / d if d != 0.0 else 1e300


@jit_inline
def _closer(s, p, ox, oy, oz, dx, dy, dz, best, kind, index):
    """(best, kind, index, hit) after testing analytic shape p: its hit if nearer than ``best``, else unchanged."""
    t = _shape_t(s, p, ox, oy, oz, dx, dy, dz, best)
    if not t < best:
        return best, kind, index, False
    n_spheres = s.spheres.shape[0]
    if p < n_spheres:
        return t, SPHERE, p, True
    return t, RECT, p - n_spheres, True


@jit
def _next_leaves(boxes, children, parent, node, depth, pending, ox, oy, oz, ix, iy, iz, best):
    """(leaves, node, depth, pending): the next leaves of the shape tree whose boxes the ray enters before ``best``,
    as bits of ``node``'s children (0: none left), and the walk's state after them; ``node`` -1 starts at the root.
    Nearest first: of a node's inner children, the walk enters the one whose box the segment enters first, testing
    the others again when it comes back (``best`` may have shrunk meanwhile: shape_tree_lanes.nearest_boxes).  A
    node's leaves, each one shape, come all at once, before its inner children: a shape costs about what a box
    test costs, and a hit among them shortens the segment for the rest.  A call of its own: inlined, this walk
    made the scenes without a tree 20 % slower in their shape tests (the loop over every shape)."""
    if node < 0:  # the loose shapes are done: into the tree's root
        node, pending = 0, 255
    while True:
        level = 8 * depth
        among = (pending >> level) & 255
        if among == 0:
            if depth == 0:
                return 0, node, depth, pending
            node = parent[node]
            depth -= 1
            continue
        if among & (among - 1) == 0:  # one inner child left: its own test culls what lies beyond ``best``
            pending &= ~(255 << level)
            node = children[node, trailing_zeros(among)]
            depth += 1
            pending |= 255 << (8 * depth)
            continue
        found = nearest_boxes(boxes, node, ox, oy, oz, ix, iy, iz, best, among, children)
        leaves = (found >> 16) & 255
        inner = (found >> 8) & 255 & ~leaves  # the segment only shrinks: a child not entered now never will be
        pending &= ~(255 << level)
        if leaves != 0:
            return leaves, node, depth, pending | (inner << level)
        if inner == 0:
            continue
        c = trailing_zeros(found & 255)
        pending |= (inner & ~(1 << c)) << level
        node = children[node, c]
        depth += 1
        pending |= 255 << (8 * depth)


@jit
def _any_leaf(boxes, children, parent, node, depth, pending, ox, oy, oz, ix, iy, iz, tmax):
    """(leaf, node, depth, pending): :func:`_next_leaves` for a ray that stops at any hit (a shadow ray), one leaf at
    a time (-1: none left): the children a node's one test finds entered, in the tree's depth-first order, as
    ``pending`` bits.  With no nearer hit to shrink the segment, testing a node again as :func:`_next_leaves` does
    would only cost (10 % on the city's shadow rays)."""
    if node < 0:
        node = 0
        pending = boxes_entered(boxes, 0, ox, oy, oz, ix, iy, iz, tmax)
    while True:
        entered = (pending >> (8 * depth)) & 255
        if entered == 0:
            if depth == 0:
                return -1, node, depth, pending
            node = parent[node]
            depth -= 1
            continue
        c = trailing_zeros(entered)
        pending ^= 1 << (8 * depth + c)
        child = children[node, c]
        if child < 0:
            return -2 - child, node, depth, pending
        node = child
        depth += 1
        pending |= boxes_entered(boxes, child, ox, oy, oz, ix, iy, iz, tmax) << (8 * depth)


@jit_inline
def _first_hit(s, ox, oy, oz, dx, dy, dz, tmax, any_hit):
    """(t, kind, index) of the nearest sphere or rectangle hit before tmax (with ``any_hit``, of the first one found;
    (tmax, MISS, -1) when there is none): every shape in turn, or through the scene's shape hierarchy when it has
    one (geometry/shape_bvh.py): its large shapes first, then the tree's leaves whose boxes the segment enters.

    The tree is walked eight children a node, and ``pending`` keeps the children not yet visited, a byte per level
    (bits 8 d .. 8 d + 7 at depth d), so the walk needs no stack: a child visited is cleared, an inner child's byte
    filled below it, and a level with none left returns to the parent.  For a nearest hit (:func:`_next_leaves`)
    the walk goes nearest child first and tests a node's children again with the segment shortened by the hits
    found since (on the same tree, the camera rays down a street of 100,000 lit windows took a quarter of the time
    they took in the tree's depth-first order, which walked far facades before the near one: decisions.md 106); a
    node's leaves come all at once, their shapes tested here.  For any hit (:func:`_any_leaf`) one test a node,
    depth-first: there is no nearer hit to wait for (the threaded binary walk over 2,000 rectangle lights: 43 boxes
    a shadow ray, each a mispredicted branch; decisions.md 90).

    One loop with one call of ``_closer`` for all three sources of candidates (every shape, the loose shapes, a
    leaf's shapes): the helpers are inlined into the kernels, and each call site is a copy that Numba compiles
    (with three sites the area-light path compiled in 208 s, with one in 178 s: decisions.md 73)."""
    best, kind, index = tmax, MISS, -1
    n_nodes = s.tree_skip.shape[0]  # no tree: every shape in turn (the stages test the same array)
    # source of candidates: 0 every shape (no tree), 1 the loose shapes, 2 the current leaf's shapes; ``leaves``:
    # the leaves of ``node`` (bits of its children) still to test
    source = 0 if n_nodes == 0 else 1
    j, end = 0, s.spheres.shape[0] + s.rects.shape[0] if n_nodes == 0 else s.tree_loose.shape[0]
    ix, iy, iz = _reciprocal(dx), _reciprocal(dy), _reciprocal(dz)
    node, depth, pending, leaves, leaf = -1, 0, 0, 0, -1
    while True:
        if j < end:
            p = j if source == 0 else (s.tree_loose[j] if source == 1 else s.tree_prims[j])
            j += 1
            best, kind, index, hit = _closer(s, p, ox, oy, oz, dx, dy, dz, best, kind, index)
            if hit and any_hit:
                return best, kind, index
            continue
        if source == 0:
            return best, kind, index
        if leaves == 0:
            if any_hit:
                leaf, node, depth, pending = _any_leaf(
                    s.tree_boxes, s.tree_child, s.tree_parent, node, depth, pending, ox, oy, oz, ix, iy, iz, best
                )
                if leaf < 0:
                    return best, kind, index
            else:
                leaves, node, depth, pending = _next_leaves(
                    s.tree_boxes, s.tree_child, s.tree_parent, node, depth, pending, ox, oy, oz, ix, iy, iz, best
                )
                if leaves == 0:
                    return best, kind, index
        if leaves != 0:
            c = trailing_zeros(leaves)
            leaves ^= 1 << c
            leaf = -2 - s.tree_child[node, c]
        source, j, end = 2, s.tree_first[leaf], s.tree_first[leaf] + s.tree_count[leaf]


@jit_inline
def closest_analytic(s, ox, oy, oz, dx, dy, dz, tmax):
    """(t, kind, index) of the nearest sphere or rectangle hit before tmax; (tmax, MISS, -1) if none."""
    return _first_hit(s, ox, oy, oz, dx, dy, dz, tmax, False)


@jit_inline
def occluded_analytic(s, ox, oy, oz, dx, dy, dz, tmax):
    """Whether a sphere or rectangle lies on the segment (0, tmax)."""
    return _first_hit(s, ox, oy, oz, dx, dy, dz, tmax, True)[0] < tmax


@jit_inline
def ball_crossed(ox, oy, oz, dx, dy, dz, spheres, g, column, tmax):
    """Does the segment [0, tmax) of a unit-direction ray come within the ball about row g's centre of ``spheres``
    (G, 5: geometry/proxies.py) whose squared radius is in ``column``?  The line's nearest point to the centre as
    in :func:`sphere_hit`; a squared radius < 0 (``NO_BALL``) is crossed by nothing."""
    fx, fy, fz = ox - spheres[g, 0], oy - spheres[g, 1], oz - spheres[g, 2]
    b = -(fx * dx + fy * dy + fz * dz)
    qx, qy, qz = fx + b * dx, fy + b * dy, fz + b * dz
    r2 = spheres[g, column]
    gap = r2 - (qx * qx + qy * qy + qz * qz)
    if not gap > 0.0:
        return False
    if fx * fx + fy * fy + fz * fz < r2:
        return True  # the origin is inside
    return b > 0.0 and b - math.sqrt(gap) < tmax


@jit_inline
def may_hit_mesh(s, ox, oy, oz, dx, dy, dz, tmax):
    """Whether the segment (0, tmax) may reach a mesh: it crosses the mesh's bounding box and the sphere around it."""
    for g in range(s.mesh_bounds.shape[0]):
        if box_hit(ox, oy, oz, dx, dy, dz, s.mesh_bounds, g, tmax) and ball_crossed(
            ox, oy, oz, dx, dy, dz, s.mesh_spheres, g, 3, tmax
        ):
            return True
    return False


@jit_inline
def blocked_by_mesh_core(s, ox, oy, oz, dx, dy, dz):
    """Whether an unbounded ray enters a closed mesh's inner ball, so that a triangle of the mesh blocks it
    (geometry/proxies.py).  Only for rays to infinity: a bounded one could end inside the mesh."""
    for g in range(s.mesh_spheres.shape[0]):
        if ball_crossed(ox, oy, oz, dx, dy, dz, s.mesh_spheres, g, 4, INF):
            return True
    return False


@jit_inline
def ray_offset(px, py, pz, nx, ny, nz, error, dx, dy, dz):
    """Origin for a ray leaving surface point p in direction d: p moved by ``error`` (the point's error bound along
    the geometric normal n, from :func:`surface` or :func:`point_error`) along n, to the side d goes to."""
    eps = error
    if dx * nx + dy * ny + dz * nz < 0.0:
        eps = -eps
    return px + eps * nx, py + eps * ny, pz + eps * nz


@jit_inline
def point_error(scale, px, py, pz, nx, ny, nz, extent):
    """A point's error bound along its normal n: ``scale`` (MESH_ERROR or ANALYTIC_ERROR) x (sum_i |n_i| |p_i| +
    ``extent``), the coordinates' rounding seen along n plus the shape's size (what its intersection routine
    subtracts from the origin).  pbrt-v4 offsets by dot(|n|, pError) the same way."""
    return scale * (abs(nx) * abs(px) + abs(ny) * abs(py) + abs(nz) * abs(pz) + extent)


@jit_inline
def surface(s, kind, index, prim, bu, bv, ox, oy, oz, dx, dy, dz, t):
    """Hit point, geometric normal, shading normal, material, two-sidedness and error bound of a hit.

    Mesh points are rebuilt from the barycentrics (b1, b2) = (bu, bv) of face ``prim`` of mesh ``index`` in double
    precision; sphere and rectangle points are projected back onto their surface, so that their error does not grow
    with the ray's length.  Normals point outward (by winding for meshes).  The error bound is the distance along
    the geometric normal that a ray leaving the point moves its origin (:func:`ray_offset`).
    """
    if kind == MESH:
        f = s.mesh_face_start[index] + prim
        i0, i1, i2 = s.mesh_faces[f, 0], s.mesh_faces[f, 1], s.mesh_faces[f, 2]
        v = s.mesh_vertices
        b0 = 1.0 - bu - bv
        px = b0 * v[i0, 0] + bu * v[i1, 0] + bv * v[i2, 0]
        py = b0 * v[i0, 1] + bu * v[i1, 1] + bv * v[i2, 1]
        pz = b0 * v[i0, 2] + bu * v[i1, 2] + bv * v[i2, 2]
        ax, ay, az = v[i1, 0] - v[i0, 0], v[i1, 1] - v[i0, 1], v[i1, 2] - v[i0, 2]
        cx, cy, cz = v[i2, 0] - v[i0, 0], v[i2, 1] - v[i0, 1], v[i2, 2] - v[i0, 2]
        ng = normalize(ay * cz - az * cy, az * cx - ax * cz, ax * cy - ay * cx)
        if s.mesh_smooth[index] == 1:
            n = s.mesh_normals
            ns = normalize(
                b0 * n[i0, 0] + bu * n[i1, 0] + bv * n[i2, 0],
                b0 * n[i0, 1] + bu * n[i1, 1] + bv * n[i2, 1],
                b0 * n[i0, 2] + bu * n[i1, 2] + bv * n[i2, 2],
            )
            if ns[0] == 0.0 and ns[1] == 0.0 and ns[2] == 0.0:
                ns = ng
        else:
            ns = ng
        error = triangle_error(
            v[i0, 0], v[i0, 1], v[i0, 2], v[i1, 0], v[i1, 1], v[i1, 2], v[i2, 0], v[i2, 1], v[i2, 2], ng
        )
        return (px, py, pz), ng, ns, s.mesh_material[index], s.mesh_two_sided[index], error
    if kind == SPHERE:
        c = s.spheres[index]
        n = normalize(ox + t * dx - c[0], oy + t * dy - c[1], oz + t * dz - c[2])
        p = (c[0] + c[3] * n[0], c[1] + c[3] * n[1], c[2] + c[3] * n[2])
        error = point_error(ANALYTIC_ERROR, p[0], p[1], p[2], n[0], n[1], n[2], c[3])
        return p, n, n, s.sphere_material[index], s.sphere_two_sided[index], error
    r = s.rects
    a, b = rect_coordinates(r, index, ox + t * dx, oy + t * dy, oz + t * dz)
    p = (
        r[index, 0] + a * r[index, 3] + b * r[index, 6],
        r[index, 1] + a * r[index, 4] + b * r[index, 7],
        r[index, 2] + a * r[index, 5] + b * r[index, 8],
    )
    n = (r[index, 9], r[index, 10], r[index, 11])
    error = point_error(ANALYTIC_ERROR, p[0], p[1], p[2], n[0], n[1], n[2], rect_extent(r, index))
    return p, n, n, s.rect_material[index], s.rect_two_sided[index], error


@jit_inline
def rect_extent(rects, i):
    """The largest component of parallelogram i's two edges: at least half its extent along any axis."""
    return max(
        abs(rects[i, 3]), abs(rects[i, 4]), abs(rects[i, 5]), abs(rects[i, 6]), abs(rects[i, 7]), abs(rects[i, 8])
    )


@jit_inline
def triangle_error(ax, ay, az, bx, by, bz, cx, cy, cz, n):
    """Error bound along normal n of a point of the float32 triangle (a, b, c) that Embree traces: MESH_ERROR x
    (sum_i |n_i| max |vertex_i| + the triangle's largest extent in a coordinate)."""
    mx, my, mz = max(abs(ax), abs(bx), abs(cx)), max(abs(ay), abs(by), abs(cy)), max(abs(az), abs(bz), abs(cz))
    extent = max(
        max(ax, bx, cx) - min(ax, bx, cx), max(ay, by, cy) - min(ay, by, cy), max(az, bz, cz) - min(az, bz, cz)
    )
    return point_error(MESH_ERROR, mx, my, mz, n[0], n[1], n[2], extent)
