"""Two spheres per triangle mesh that decide most shadow rays without Embree: one around it, one inside it.

An environment's shadow ray leaves a surface and goes to infinity.  If it misses a sphere that holds every vertex
of a mesh, it misses the mesh (a triangle lies in the convex hull of its vertices).  If the mesh is *closed* -- every
directed edge (i, j) of its faces matched by as many (j, i), so that its surface bounds a volume and the generalized
winding number (Jacobson et al. 2013) is an integer off the surface -- and a ball lies where that number is not 0,
then a ray that enters the ball must leave the volume again before infinity: it crosses a triangle, and Embree's
watertight traversal (``RTC_SCENE_FLAG_ROBUST``, shared vertices bit-identical) finds that crossing.  So a shadow
ray through the inner ball is blocked whatever Embree would have been asked.  Neither sphere changes an answer, only
who gives it; both are padded by far more than float32 rounding of the vertices Embree holds.

On the peer scene's 98k-triangle blob (closed; its vertices 0.88-1.11 from its centre) the inner ball takes 72 % of
the mesh's blocked shadow rays and the outer sphere 27 % of the rays its bounding box let through (decisions.md 59).
"""

from __future__ import annotations

import numpy as np

__all__ = ["NO_BALL", "closest_distances", "is_closed", "mesh_spheres", "winding_number"]

NO_BALL = -1.0  # the squared radius of a mesh's inner ball when it has none: no ray passes within it
_PAD = 1e-5  # relative: float32 vertices (6e-8) and the ray tests' float64 rounding, many times over


def is_closed(faces: np.ndarray) -> bool:
    """Whether every directed edge (i, j) of the faces has as many opposite edges (j, i): a surface without
    boundary, consistently oriented, whose winding number is an integer off the surface."""
    faces = np.asarray(faces, dtype=np.int64)
    if faces.size == 0:
        return False
    start = faces.reshape(-1)
    end = np.roll(faces, -1, axis=1).reshape(-1)
    base = int(faces.max()) + 1
    forward = np.sort(start * base + end)
    backward = np.sort(end * base + start)
    return bool(np.array_equal(forward, backward))


def winding_number(vertices: np.ndarray, faces: np.ndarray, point) -> float:
    """The generalized winding number of ``point``: the faces' signed solid angles seen from it over 4 pi (Van
    Oosterom and Strackee 1983: tan(omega / 2) = a . (b x c) / (|a||b||c| + (a.b)|c| + (a.c)|b| + (b.c)|a|))."""
    p = np.asarray(point, dtype=np.float64)
    a, b, c = (vertices[faces[:, i]] - p for i in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    numerator = np.einsum("ij,ij->i", a, np.cross(b, c))
    denominator = (
        la * lb * lc
        + np.einsum("ij,ij->i", a, b) * lc
        + np.einsum("ij,ij->i", a, c) * lb
        + np.einsum("ij,ij->i", b, c) * la
    )
    return float(2.0 * np.arctan2(numerator, denominator).sum() / (4.0 * np.pi))


def closest_distances(vertices: np.ndarray, faces: np.ndarray, point) -> np.ndarray:
    """Distance from ``point`` to each triangle (Ericson, Real-Time Collision Detection 5.1.5: the closest point
    is in one of seven Voronoi regions -- a vertex, an edge or the face), vectorized over the faces."""
    p = np.asarray(point, dtype=np.float64)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    ab, ac, ap = b - a, c - a, p - a

    def dot(x, y):
        return np.einsum("ij,ij->i", x, y)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        # the face region by default, then the regions that take precedence overwrite it (Ericson's early returns
        # in reverse order)
        total = va + vb + vc
        v = vb / total
        w = vc / total
        closest = a + ab * v[:, None] + ac * w[:, None]
        regions = [
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b, c - b, (d4 - d3) / ((d4 - d3) + (d5 - d6))),  # edge bc
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a, ac, d2 / (d2 - d6)),  # edge ac
            ((d6 >= 0) & (d5 <= d6), c, 0.0 * ab, np.zeros_like(d1)),  # vertex c
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a, ab, d1 / (d1 - d3)),  # edge ab
            ((d3 >= 0) & (d4 <= d3), b, 0.0 * ab, np.zeros_like(d1)),  # vertex b
            ((d1 <= 0) & (d2 <= 0), a, 0.0 * ab, np.zeros_like(d1)),  # vertex a
        ]
        for where, origin, edge, t in regions:
            closest = np.where(where[:, None], origin + edge * np.nan_to_num(t)[:, None], closest)
    distances = np.linalg.norm(p - closest, axis=1)
    # a degenerate face (no area: its barycentric weights divide by 0) is a segment or a point: the nearest of its
    # three edges
    bad = ~np.isfinite(distances)
    if bad.any():
        distances[bad] = np.min([_segment_distance(p, x[bad], y[bad]) for x, y in ((a, b), (b, c), (c, a))], axis=0)
    return distances


def _segment_distance(p, x, y):
    edge = y - x
    length2 = np.einsum("ij,ij->i", edge, edge)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.nan_to_num(np.einsum("ij,ij->i", p - x, edge) / length2), 0.0, 1.0)
    return np.linalg.norm(p - (x + edge * t[:, None]), axis=1)


def mesh_spheres(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(centre x, y, z, outer radius^2, inner radius^2): a sphere holding every vertex and, for a closed mesh, a ball
    inside it (else inner radius^2 = NO_BALL).  The centre is the bounding box's or the vertices' mean, whichever
    gives the larger ball (the outer sphere is centred there too)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    size = float(np.max(hi - lo)) + float(np.max(np.abs(np.concatenate([lo, hi]))))
    pad = _PAD * size
    candidates = [0.5 * (lo + hi), vertices.mean(axis=0)]
    best_centre, best_inner = candidates[0], 0.0
    if is_closed(faces):
        for centre in candidates:
            winding = winding_number(vertices, faces, centre)
            if abs(winding - round(winding)) > 1e-3 or round(winding) == 0:
                continue  # not inside (or the mesh is not what is_closed says)
            inner = float(closest_distances(vertices, faces, centre).min()) - pad
            if inner > best_inner:
                best_centre, best_inner = centre, inner
    outer = float(np.sqrt(np.max(np.sum((vertices - best_centre) ** 2, axis=1)))) + pad
    inner2 = best_inner**2 if best_inner > 0.0 else NO_BALL
    return np.array([*best_centre, outer**2, inner2])
