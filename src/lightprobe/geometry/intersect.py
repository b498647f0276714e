"""Ray-shape intersection kernels for the analytic shapes, bounding-box culling, and surface reconstruction.

Meshes are intersected by Embree (:mod:`lightprobe.geometry.raytracer`); spheres and rectangles exactly here, in
double precision.  Before a ray goes to Embree its segment is tested against every mesh's bounding box, so rays
that cannot reach a mesh (most shadow rays from a ground plane toward the sky, for instance) never leave Numba.

Hit kinds: ``MISS`` (0), ``MESH`` (1), ``SPHERE`` (2), ``RECT`` (3).
"""

from __future__ import annotations

import math

from .._numba import jit, jit_inline
from .frame import normalize

__all__ = ["MESH", "MISS", "RECT", "SPHERE", "closest_analytic", "occluded_analytic", "ray_offset", "surface"]

MISS, MESH, SPHERE, RECT = 0, 1, 2, 3
INF = math.inf
# Secondary rays start this far from the surface, relative to the largest coordinate of the point (plus 1 so the
# origin is covered): about 64 float32 ulps, far above the ~1e-7 relative error of Embree's float32 hits and of our
# float64 reconstruction, and far below any feature size that matters.
OFFSET_SCALE = 2.0**-16


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
def rect_hit(ox, oy, oz, dx, dy, dz, rects, i, tmax):
    """Distance to rectangle i of ``rects`` (R, 12: origin, edge u, edge v, normal), INF if missed before tmax."""
    nx, ny, nz = rects[i, 9], rects[i, 10], rects[i, 11]
    denom = dx * nx + dy * ny + dz * nz
    if denom == 0.0:
        return INF
    t = ((rects[i, 0] - ox) * nx + (rects[i, 1] - oy) * ny + (rects[i, 2] - oz) * nz) / denom
    if not (0.0 < t < tmax):
        return INF
    px, py, pz = ox + t * dx - rects[i, 0], oy + t * dy - rects[i, 1], oz + t * dz - rects[i, 2]
    ux, uy, uz, vx, vy, vz = rects[i, 3], rects[i, 4], rects[i, 5], rects[i, 6], rects[i, 7], rects[i, 8]
    a = (px * ux + py * uy + pz * uz) / (ux**2 + uy**2 + uz**2)
    b = (px * vx + py * vy + pz * vz) / (vx**2 + vy**2 + vz**2)
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
def closest_analytic(s, ox, oy, oz, dx, dy, dz, tmax):
    """(t, kind, index) of the nearest sphere or rectangle hit before tmax."""
    best = tmax
    kind = MISS
    index = -1
    for i in range(s.spheres.shape[0]):
        t = sphere_hit(ox, oy, oz, dx, dy, dz, s.spheres[i, 0], s.spheres[i, 1], s.spheres[i, 2], s.spheres[i, 3], best)
        if t < best:
            best, kind, index = t, SPHERE, i
    for i in range(s.rects.shape[0]):
        t = rect_hit(ox, oy, oz, dx, dy, dz, s.rects, i, best)
        if t < best:
            best, kind, index = t, RECT, i
    return best, kind, index


@jit_inline
def occluded_analytic(s, ox, oy, oz, dx, dy, dz, tmax):
    for i in range(s.spheres.shape[0]):
        if (
            sphere_hit(ox, oy, oz, dx, dy, dz, s.spheres[i, 0], s.spheres[i, 1], s.spheres[i, 2], s.spheres[i, 3], tmax)
            < tmax
        ):
            return True
    for i in range(s.rects.shape[0]):
        if rect_hit(ox, oy, oz, dx, dy, dz, s.rects, i, tmax) < tmax:
            return True
    return False


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


@jit
def ray_offset(px, py, pz, nx, ny, nz, dx, dy, dz):
    """Origin for a ray leaving surface point p in direction d: p moved along the geometric normal n, toward
    the side d goes to, by OFFSET_SCALE x (1 + max |p_i|)."""
    eps = OFFSET_SCALE * (1.0 + max(abs(px), abs(py), abs(pz)))
    if dx * nx + dy * ny + dz * nz < 0.0:
        eps = -eps
    return px + eps * nx, py + eps * ny, pz + eps * nz


@jit_inline
def surface(s, kind, index, prim, bu, bv, ox, oy, oz, dx, dy, dz, t):
    """Hit point, geometric normal, shading normal, material and two-sidedness of a hit.

    Mesh points are rebuilt from the barycentrics (b1, b2) = (bu, bv) of face ``prim`` of mesh ``index`` in double
    precision; sphere points are projected back onto the sphere.  Normals point outward (by winding for meshes).
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
        return (px, py, pz), ng, ns, s.mesh_material[index], s.mesh_two_sided[index]
    if kind == SPHERE:
        c = s.spheres[index]
        n = normalize(ox + t * dx - c[0], oy + t * dy - c[1], oz + t * dz - c[2])
        p = (c[0] + c[3] * n[0], c[1] + c[3] * n[1], c[2] + c[3] * n[2])
        return p, n, n, s.sphere_material[index], s.sphere_two_sided[index]
    r = s.rects[index]
    n = (r[9], r[10], r[11])
    return (ox + t * dx, oy + t * dy, oz + t * dz), n, n, s.rect_material[index], s.rect_two_sided[index]
