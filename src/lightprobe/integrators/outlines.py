"""A control variate for the outlines of emitters the camera sees directly.

Where an emitter's outline crosses a pixel, the pixel's estimate is mostly the count of its camera samples that hit
the emitter: a sphere light of radiance 60 covering a thousandth of a pixel is one hit in hundreds of samples, and
on the benchmark's area-light scene such pixels (0.6 % of the image) held two thirds of the relMSE (decisions.md 91,
94, 96).
Better light sampling cannot touch that error; only the camera samples' positions can.

So each camera sample's value f(x) at film position x of pixel p becomes

    f(x) - g(x) + G_p,     g(x) = sum over the pixel's outlines e of L_e [the ray through x meets e's shape],
                           G_p  = sum over the same e of L_e a_pe,   a_pe = the pixel's area that e's shape covers,

an unbiased estimate of the pixel for any g whose pixel integral G_p is known exactly (a control variate). The
camera's box filter makes the pixel's estimate the mean over its samples, so E[g] = G_p: the mean is unchanged and
what the hits used to estimate (L_e a_pe) is now known. Where the emitter is the nearest hit, f = L_e + (its own
reflection) and f - g is that reflection; elsewhere f - g = f: only the occluded parts of an outline keep their old
noise. Nothing assumes the emitter is visible, constant or even there: a shape that is hidden, textured or
overlapped is an unbiased g that removes less, or adds noise: where a wall hides an emitter, f - g = f - L_e on the
hidden part, the noise that the variate removes where the emitter is seen. So an entry is kept only where the camera
sees its emitter: every one of a few probe rays through the pixel's covered region (its centre, corners and edges)
meets the emitter first (:func:`_seen`).

The shapes (a rectangle's or triangle's projection is a convex polygon; a sphere's, an ellipse) are kept where the
whole shape lies in front of the camera's plane and its emitting side faces the camera. A pixel's coverage ``a_pe``
is exact geometry: a polygon clipped to the pixel's square (Sutherland-Hodgman) and its area; an ellipse mapped to
the unit disk, where the square becomes a parallelogram whose intersection with the disk has a closed form (each
edge's triangle with the centre: chord parts and circular sectors). A sample's membership is tested in 3D on its
ray's direction (the cone of directions toward the shape), the same set as the film-space one.

Only pixels an outline crosses (0 < a < 1) keep an entry, and none where two emitters' shapes may overlap (one
covering the pixel whole included): where a near emitter hides a far one, g would count both and f sees one, new
noise instead of less. At most :data:`MAX_PER_PIXEL` entries a pixel (the nearest shapes'): any subset of pixels and
shapes is still an unbiased g.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._numba import jit, jit_alloc, jit_inline
from ..emitters.kinds import rows_of
from ..geometry.intersect import MESH, RECT, SPHERE

__all__ = ["CONE", "MAX_PER_PIXEL", "POLYGON", "OutlineTable", "empty", "outline_offset", "pass_fields", "table"]

MAX_PER_PIXEL = 16  # outline entries a pixel tests per camera sample at most
MAX_ENTRIES_PER_PIXEL = 8  # the whole table's entries, per pixel of the image (the rest of the shapes go without)
CONE, POLYGON = 0, 1  # a shape row's kind: [CONE, w (3), sin^2 of the half-angle, 0 ...] | [POLYGON, 4 normals]
ROW = 13
MIN_COVER = 1e-12  # smaller shares are a corner's rounding: no entry (a sample would all but never meet them)


class OutlineTable(NamedTuple):
    """Pixel p's entries are start[p] .. start[p + 1] - 1 (all arrays empty: no outline)."""

    start: np.ndarray  # (pixels + 1,) int64
    shape: np.ndarray  # (entries,) int64: the entry's row of geom
    cover: np.ndarray  # (entries,) float64: the share of the pixel the shape covers, in (0, 1)
    geom: np.ndarray  # (shapes, ROW) float64: how a direction is tested (CONE or POLYGON)
    radiance: np.ndarray  # (shapes, 3) float64: the emitter's radiance toward the camera


def empty() -> OutlineTable:
    return OutlineTable(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, ROW)), np.zeros((0, 3)))


# --- per camera sample (the shading-setup stage) ---------------------------------------------------------------------
@jit_inline
def _inside(row, dx, dy, dz):
    """Whether unit direction d from the camera meets the shape of ``row``."""
    if row[0] == CONE:
        dot = dx * row[1] + dy * row[2] + dz * row[3]
        cx = dy * row[3] - dz * row[2]
        cy = dz * row[1] - dx * row[3]
        cz = dx * row[2] - dy * row[1]
        return dot > 0.0 and cx * cx + cy * cy + cz * cz <= row[4]
    for i in range(4):
        if dx * row[1 + 3 * i] + dy * row[2 + 3 * i] + dz * row[3 + 3 * i] < 0.0:
            return False
    return True


@jit
def outline_offset(start, shape, cover, geom, radiance, pixel, dx, dy, dz):
    """G_p - g(d): what a camera sample of ``pixel`` along unit direction d adds to what it sees directly.  Called,
    not inlined: the shading-setup stage calls it in two places, and each inlined copy was compiled again
    (decisions.md 130)."""
    r = 0.0
    g = 0.0
    b = 0.0
    for e in range(start[pixel], start[pixel + 1]):
        row = shape[e]
        w = cover[e] - (1.0 if _inside(geom[row], dx, dy, dz) else 0.0)
        r += w * radiance[row, 0]
        g += w * radiance[row, 1]
        b += w * radiance[row, 2]
    return r, g, b


# --- coverage: exact areas in film coordinates (pixel (i, j) is the unit square at (i, j)) ------------------------
@jit
def _clip(ax, ay, n, planes, ox, oy):
    """Clip the convex polygon (ax, ay)[:n] to the half-planes a x + b y + c >= 0 of ``planes`` (k, 3), one at a time
    (Sutherland-Hodgman), in place; returns the clipped polygon's vertex count (below 3: nothing left).  ax, ay, ox,
    oy: room for at least n + k vertices."""
    for h in range(planes.shape[0]):
        a, b, c = planes[h, 0], planes[h, 1], planes[h, 2]
        m = 0
        for i in range(n):
            j = (i + 1) % n
            si = a * ax[i] + b * ay[i] + c
            sj = a * ax[j] + b * ay[j] + c
            if si >= 0.0:
                ox[m], oy[m] = ax[i], ay[i]
                m += 1
            if (si >= 0.0) != (sj >= 0.0):
                t = si / (si - sj)
                ox[m], oy[m] = ax[i] + t * (ax[j] - ax[i]), ay[i] + t * (ay[j] - ay[i])
                m += 1
        n = m
        if n < 3:
            return n
        for i in range(n):
            ax[i], ay[i] = ox[i], oy[i]
    return n


@jit_alloc
def _clip_area(px, py, n, planes, ox, oy):
    """Area of the convex polygon (px, py)[:n] clipped to the half-planes of ``planes`` (:func:`_clip`); ox, oy:
    scratch of at least n + k."""
    ax = px.copy()
    ay = py.copy()
    n = _clip(ax, ay, n, planes, ox, oy)
    if n < 3:
        return 0.0
    area = 0.0
    for i in range(n):
        j = (i + 1) % n
        area += ax[i] * ay[j] - ax[j] * ay[i]
    return 0.5 * abs(area)


@jit_alloc
def _square_planes(x0, y0):
    """The unit square at (x0, y0) as four half-planes."""
    planes = np.empty((4, 3))
    planes[0, 0], planes[0, 1], planes[0, 2] = 1.0, 0.0, -x0
    planes[1, 0], planes[1, 1], planes[1, 2] = -1.0, 0.0, x0 + 1.0
    planes[2, 0], planes[2, 1], planes[2, 2] = 0.0, 1.0, -y0
    planes[3, 0], planes[3, 1], planes[3, 2] = 0.0, -1.0, y0 + 1.0
    return planes


@jit
def _sector(ax, ay, bx, by):
    """Signed area of the unit disk's sector between the rays to a and b."""
    return 0.5 * math.atan2(ax * by - ay * bx, ax * bx + ay * by)


@jit
def _disk_triangle(ax, ay, bx, by):
    """Signed area of the unit disk (centre 0) intersected with the triangle (0, a, b): the chord's part inside the
    disk as a triangle, the parts outside as sectors."""
    dx, dy = bx - ax, by - ay
    qa = dx * dx + dy * dy
    if qa == 0.0:
        return 0.0
    qb = ax * dx + ay * dy
    qc = ax * ax + ay * ay - 1.0
    disc = qb * qb - qa * qc
    if disc <= 0.0:
        return _sector(ax, ay, bx, by)
    root = math.sqrt(disc)
    t1 = (-qb - root) / qa
    t2 = (-qb + root) / qa
    if t1 >= 1.0 or t2 <= 0.0:
        return _sector(ax, ay, bx, by)
    t1 = max(t1, 0.0)
    t2 = min(t2, 1.0)
    p1x, p1y = ax + t1 * dx, ay + t1 * dy
    p2x, p2y = ax + t2 * dx, ay + t2 * dy
    area = 0.5 * (p1x * p2y - p1y * p2x)
    if t1 > 0.0:
        area += _sector(ax, ay, p1x, p1y)
    if t2 < 1.0:
        area += _sector(p2x, p2y, bx, by)
    return area


@jit
def disk_polygon_area(px, py, n):
    """Area of the unit disk intersected with the counter-clockwise polygon (px, py)[:n]."""
    area = 0.0
    for i in range(n):
        j = (i + 1) % n
        area += _disk_triangle(px[i], py[i], px[j], py[j])
    return area


@jit_alloc
def _polygon_entries(fx, fy, width, height):
    """(pixels, covers) of the pixels the convex film polygon (fx, fy) covers, in part or whole."""
    n = fx.shape[0]
    i0 = max(0, math.floor(fx.min()))
    i1 = min(width, math.floor(fx.max()) + 1)
    j0 = max(0, math.floor(fy.min()))
    j1 = min(height, math.floor(fy.max()) + 1)
    count = max(0, i1 - i0) * max(0, j1 - j0)
    pixels = np.empty(count, np.int64)
    covers = np.empty(count)
    ox = np.empty(n + 8)
    oy = np.empty(n + 8)
    px = np.empty(n + 8)
    py = np.empty(n + 8)
    for k in range(n):  # not a slice assignment: see _overlap
        px[k] = fx[k]
        py[k] = fy[k]
    m = 0
    for j in range(j0, j1):
        for i in range(i0, i1):
            a = _clip_area(px, py, n, _square_planes(float(i), float(j)), ox, oy)
            if a > MIN_COVER:
                pixels[m] = j * width + i
                covers[m] = a
                m += 1
    return pixels[:m], covers[:m]


@jit_alloc
def _ellipse_entries(cx, cy, l00, l10, l11, half_x, half_y, width, height):
    """(pixels, covers) of the pixels the ellipse {x : |L^T (x - c)| <= 1} covers, in part or whole (L lower
    triangular)."""
    i0 = max(0, math.floor(cx - half_x))
    i1 = min(width, math.floor(cx + half_x) + 1)
    j0 = max(0, math.floor(cy - half_y))
    j1 = min(height, math.floor(cy + half_y) + 1)
    count = max(0, i1 - i0) * max(0, j1 - j0)
    pixels = np.empty(count, np.int64)
    covers = np.empty(count)
    zx = np.empty(4)
    zy = np.empty(4)
    scale = 1.0 / (l00 * l11)  # film area of a unit of disk area: 1 / det L^T
    m = 0
    for j in range(j0, j1):
        for i in range(i0, i1):
            inside = 0
            for c in range(4):  # the square's corners counter-clockwise, mapped by L^T
                x = i + (1.0 if c == 1 or c == 2 else 0.0) - cx
                y = j + (1.0 if c >= 2 else 0.0) - cy
                zx[c] = l00 * x + l10 * y
                zy[c] = l11 * y
                if zx[c] * zx[c] + zy[c] * zy[c] <= 1.0:
                    inside += 1
            # the ellipse is convex: with its four corners the whole square is in it
            a = 1.0 if inside == 4 else min(1.0, disk_polygon_area(zx, zy, 4) * scale)
            if a > MIN_COVER:
                pixels[m] = j * width + i
                covers[m] = a
                m += 1
    return pixels[:m], covers[:m]


# --- the table ----------------------------------------------------------------------------------------------------
class _Film:
    """The pinhole camera's map between film coordinates (X, Y) and ray directions (geometry/camera.py)."""

    def __init__(self, camera):
        self.eye = np.asarray(camera.origin, np.float64)
        self.forward, self.right, self.up = camera.basis()
        cam = camera.kernel_array()
        self.tan_x, self.tan_y = float(cam[12]), float(cam[13])
        self.width, self.height = camera.resolution

    def coordinates(self, q: np.ndarray, qf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Film coordinates (X, Y) of points q (..., 3) relative to the camera, qf (...) their distance along its
        forward axis (> 0): camera_ray's map inverted."""
        x = ((q @ self.right) / (qf * self.tan_x) + 1.0) * self.width / 2.0
        y = (1.0 - (q @ self.up) / (qf * self.tan_y)) * self.height / 2.0
        return x, y


@jit_alloc
def _overlap(a, b, x0, y0, poly_x, poly_y, poly_n, boxes):
    """Whether shapes a and b may both cover some of the unit square at (x0, y0): two polygons' regions are clipped
    to it and to each other; an ellipse is taken to meet whatever its bounding box meets."""
    if (boxes[a, 1] <= boxes[b, 0] or boxes[b, 1] <= boxes[a, 0]
            or boxes[a, 3] <= boxes[b, 2] or boxes[b, 3] <= boxes[a, 2]):  # fmt: skip
        return False
    if poly_n[a] == 0 or poly_n[b] == 0:
        return True
    nb = poly_n[b]
    planes = np.empty((4 + nb, 3))
    square = _square_planes(x0, y0)
    for i in range(4):  # not a slice assignment, which compiles Numba's shape-mismatch message (1.3 s, once)
        for k in range(3):
            planes[i, k] = square[i, k]
    for i in range(nb):  # b counter-clockwise: its inside is left of each edge
        j = (i + 1) % nb
        ex, ey = poly_x[b, j] - poly_x[b, i], poly_y[b, j] - poly_y[b, i]
        planes[4 + i, 0], planes[4 + i, 1] = -ey, ex
        planes[4 + i, 2] = ey * poly_x[b, i] - ex * poly_y[b, i]
    na = poly_n[a]
    ox = np.empty(na + 4 + nb)
    oy = np.empty(na + 4 + nb)
    return _clip_area(poly_x[a, :na].copy(), poly_y[a, :na].copy(), na, planes, ox, oy) > MIN_COVER


@jit_alloc
def _separate(start, shape, width, poly_x, poly_y, poly_n, boxes):
    """Which entries to keep: in each pixel, none whose shape may overlap another shape's there (covered whole or in
    part).  Where one emitter hides another, g would count both and f sees one: new noise instead of less; and which
    one is in front is not asked (an order by distance, tried first, kept the wrong one of two panels that overlap)."""
    keep = np.ones(shape.shape[0], np.bool_)
    for p in range(start.shape[0] - 1):
        lo, hi = start[p], start[p + 1]
        x0, y0 = float(p % width), float(p // width)
        for e in range(lo + 1, hi):
            for f in range(lo, e):
                if _overlap(shape[e], shape[f], x0, y0, poly_x, poly_y, poly_n, boxes):
                    keep[e] = False
                    keep[f] = False
    return keep


class _Shapes(NamedTuple):
    """The shapes of the lights the camera sees whole from their emitting side, one row each."""

    rows: np.ndarray  # (S, ROW) how a direction is tested
    light: np.ndarray  # (S,) int64 the light's row of the light table
    depth: np.ndarray  # (S,) distance from the camera to the shape's nearest point (a corner's; a sphere's surface)
    poly_x: np.ndarray  # (S, 4) film polygon, counter-clockwise (poly_n vertices; 0: an ellipse)
    poly_y: np.ndarray
    poly_n: np.ndarray  # (S,) int64
    ellipses: np.ndarray  # (S, 7) an ellipse's centre (x, y), L^T's l00, l10, l11, and its half-width and height

    def take(self, keep) -> _Shapes:
        return _Shapes(*(a[keep] for a in self))


def _polygons(film: _Film, lights, index: np.ndarray, corners: np.ndarray) -> _Shapes:
    """The planar lights ``index`` with ``corners`` (S, n, 3), all at once: kept where the emitting side faces the
    camera (one-sided: the side of the row's normal), every corner is well in front of the camera's plane and the
    projection is not edge-on."""
    count, n = corners.shape[0], corners.shape[1]
    q = corners - film.eye
    toward = -np.einsum("ij,ij->i", lights.geom[index, 9:12], q[:, 0])
    keep = (toward > 0.0) | ((toward < 0.0) & (lights.two_sided[index] == 1))
    qf = q @ film.forward
    keep &= np.all(qf > 1e-6 * np.linalg.norm(q, axis=2), axis=1)
    qf = np.where(keep[:, None], qf, 1.0)
    fx, fy = film.coordinates(q, qf)
    twice = np.sum(fx * np.roll(fy, -1, axis=1) - np.roll(fx, -1, axis=1) * fy, axis=1)
    keep &= np.abs(twice) > 1e-12  # not seen edge-on
    clockwise = twice < 0.0  # as drawn in (X, Y): reversed, so every film polygon is counter-clockwise
    fx[clockwise], fy[clockwise] = fx[clockwise, ::-1], fy[clockwise, ::-1]
    normals = np.cross(q, np.roll(q, -1, axis=1))  # each edge's plane through the camera
    normals *= np.sign(np.einsum("snk,sk->sn", normals, q.mean(axis=1)))[..., None]  # the shape's side positive
    rows = np.zeros((count, ROW))
    rows[:, 0] = POLYGON
    rows[:, 1 : 1 + 3 * n] = normals.reshape(count, 3 * n)
    poly_x, poly_y = np.zeros((count, 4)), np.zeros((count, 4))
    poly_x[:, :n], poly_y[:, :n] = fx, fy
    poly_x[:, n:], poly_y[:, n:] = fx[:, :1], fy[:, :1]  # a triangle's unused corner: its first (for its box)
    depth = np.min(np.linalg.norm(q, axis=2), axis=1)
    shapes = _Shapes(rows, index, depth, poly_x, poly_y, np.full(count, n, np.int64), np.zeros((count, 7)))
    return shapes.take(keep)


def _spheres(film: _Film, lights, index: np.ndarray) -> _Shapes:
    """The sphere lights ``index``, all at once: kept where the whole sphere is in front of the camera's plane, so
    that its projection is an ellipse.  A film point (x, y) relative to the centre's projection has the direction
    d = b0 + x aX + y aY, which meets the sphere where Q = s2 |d|^2 - |d x w|^2 >= 0 (w toward the centre, s2 the
    squared sine of the sphere's angular radius; d . w > 0 holds in front): Q = x^T K x + 2 k . x + q0, the ellipse
    (x - c)^T S (x - c) <= 1 with c = -K^-1 k and S = -K / (q0 - k . K^-1 k)."""
    count = index.shape[0]
    centre, radius = lights.geom[index, 0:3], lights.geom[index, 3]
    q = centre - film.eye
    dist = np.linalg.norm(q, axis=1)
    qf = q @ film.forward
    keep = (dist > radius * (1.0 + 1e-9)) & (qf > radius + 1e-6 * dist)
    qf = np.where(keep, qf, 1.0)
    x0, y0 = film.coordinates(q, qf)
    w = q / dist[:, None]
    s2 = (radius / dist) ** 2
    a_x = (2.0 * film.tan_x / film.width) * film.right
    a_y = -(2.0 * film.tan_y / film.height) * film.up
    b0 = film.forward + ((2.0 * x0 / film.width - 1.0) * film.tan_x)[:, None] * film.right
    b0 = b0 + ((1.0 - 2.0 * y0 / film.height) * film.tan_y)[:, None] * film.up
    u, v, z0 = np.cross(a_x, w), np.cross(a_y, w), np.cross(b0, w)

    def dot(a, b):
        return np.sum(a * b, axis=-1)

    k00 = s2 * (a_x @ a_x) - dot(u, u)
    k01 = s2 * (a_x @ a_y) - dot(u, v)
    k11 = s2 * (a_y @ a_y) - dot(v, v)
    k0 = s2 * (b0 @ a_x) - dot(u, z0)
    k1 = s2 * (b0 @ a_y) - dot(v, z0)
    q0 = s2 * dot(b0, b0) - dot(z0, z0)
    det = k00 * k11 - k01 * k01
    keep &= (k00 < 0.0) & (det > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        solve0, solve1 = (k11 * k0 - k01 * k1) / det, (k00 * k1 - k01 * k0) / det  # K^-1 k
        c0 = q0 - (k0 * solve0 + k1 * solve1)
        keep &= c0 > 0.0
        s00, s01, s11 = -k00 / c0, -k01 / c0, -k11 / c0
        l00 = np.sqrt(s00)
        l10 = s01 / l00
        l11 = np.sqrt(s11 - l10 * l10)  # S = L L^T (Cholesky)
        det_s = s00 * s11 - s01 * s01
        ellipses = np.stack(
            [x0 - solve0, y0 - solve1, l00, l10, l11, np.sqrt(s11 / det_s), np.sqrt(s00 / det_s)], axis=1
        )
    keep &= np.all(np.isfinite(ellipses), axis=1)
    rows = np.zeros((count, ROW))
    rows[:, 0], rows[:, 1:4], rows[:, 4] = CONE, w, s2
    # an ellipse's "polygon" is only its box's corners (poly_n 0: the box is all _overlap reads of it)
    poly_x = np.stack([ellipses[:, 0] - ellipses[:, 5], ellipses[:, 0] + ellipses[:, 5]] * 2, axis=1)
    poly_y = np.stack([ellipses[:, 1] - ellipses[:, 6]] * 2 + [ellipses[:, 1] + ellipses[:, 6]] * 2, axis=1)
    shapes = _Shapes(rows, index, dist - radius, poly_x, poly_y, np.zeros(count, np.int64), ellipses)
    return shapes.take(keep)


def _shapes(film: _Film, lights) -> _Shapes:
    """Every area light the camera sees whole from its emitting side, nearest first."""
    emitting = np.any(lights.radiance != 0.0, axis=1)
    parts = []
    for name in ("rectangle", "triangle", "sphere"):
        index = np.flatnonzero(rows_of(lights.kind, name) & emitting)
        g = lights.geom[index]
        if name == "rectangle":
            o, eu, ev = g[:, 0:3], g[:, 3:6], g[:, 6:9]
            parts.append(_polygons(film, lights, index, np.stack([o, o + eu, o + eu + ev, o + ev], axis=1)))
        elif name == "triangle":
            parts.append(_polygons(film, lights, index, np.stack([g[:, 0:3], g[:, 3:6], g[:, 6:9]], axis=1)))
        else:
            parts.append(_spheres(film, lights, index))
    shapes = _Shapes(*(np.concatenate(column) for column in zip(*parts, strict=True)))
    return shapes.take(np.argsort(shapes.depth, kind="stable"))


@jit_alloc
def _entries(poly_x, poly_y, poly_n, ellipses, width, height, limit):
    """(pixels, covers, shapes) of every shape in order: the pixels it covers in part or whole.  The shapes whose
    entries would take the total past ``limit`` go without."""
    size = 1024
    pixels = np.empty(size, np.int64)
    covers = np.empty(size)
    shapes = np.empty(size, np.int64)
    m = 0
    for s in range(poly_n.shape[0]):
        n = poly_n[s]
        if n > 0:
            pix, cov = _polygon_entries(poly_x[s, :n].copy(), poly_y[s, :n].copy(), width, height)
        else:
            e = ellipses[s]
            pix, cov = _ellipse_entries(e[0], e[1], e[2], e[3], e[4], e[5], e[6], width, height)
        k = pix.shape[0]
        if m + k > limit:
            break
        if m + k > size:
            while m + k > size:
                size *= 2
            grown_p, grown_c, grown_s = np.empty(size, np.int64), np.empty(size), np.empty(size, np.int64)
            for i in range(m):  # element by element, not slice assignments: see _overlap
                grown_p[i], grown_c[i], grown_s[i] = pixels[i], covers[i], shapes[i]
            pixels, covers, shapes = grown_p, grown_c, grown_s
        for i in range(k):
            pixels[m + i], covers[m + i], shapes[m + i] = pix[i], cov[i], s
        m += k
    return pixels[:m], covers[:m], shapes[:m]


# --- visibility: an entry is kept only where the camera sees its emitter ---------------------------------------------
PROBE_CORNERS = 8  # the corners (and edge midpoints) of an entry's region that its probes take at most
ELLIPSE_SIDES = 32  # an ellipse's inscribed polygon, for placing probes inside it
PULL = 0.9  # a probe at a corner or an edge's midpoint, moved this far from the region's centre toward it


@jit_alloc
def _probe_points(pixels, shapes, poly_x, poly_y, poly_n, ellipses, width):
    """Film points inside each entry's region, the part of its pixel that its shape covers: the region's centre, and
    its corners and edges' midpoints pulled toward the centre (at most ``PROBE_CORNERS`` of each, evenly taken).
    Returns (x, y, entry) per point; an entry whose region is too thin to hold a point gets none (an ellipse's
    region is that of its inscribed polygon, which misses slivers a thousandth of its radius deep)."""
    entries = pixels.shape[0]
    most = entries * (1 + 2 * PROBE_CORNERS)
    xs = np.empty(most)
    ys = np.empty(most)
    owner = np.empty(most, np.int64)
    room = ELLIPSE_SIDES + 8
    ax, ay, ox, oy = np.empty(room), np.empty(room), np.empty(room), np.empty(room)
    m = 0
    for e in range(entries):
        s = shapes[e]
        n = poly_n[s]
        if n > 0:
            for i in range(n):
                ax[i], ay[i] = poly_x[s, i], poly_y[s, i]
        else:  # x = c + L^-T z for z on the unit circle: the ellipse's boundary, as _ellipse_entries maps it
            cx, cy, l00, l10, l11 = ellipses[s, 0], ellipses[s, 1], ellipses[s, 2], ellipses[s, 3], ellipses[s, 4]
            n = ELLIPSE_SIDES
            for i in range(n):
                angle = 2.0 * math.pi * i / n
                y = math.sin(angle) / l11
                ax[i] = cx + (math.cos(angle) - l10 * y) / l00
                ay[i] = cy + y
        p = pixels[e]
        n = _clip(ax, ay, n, _square_planes(float(p % width), float(p // width)), ox, oy)
        if n < 3:
            continue
        cx = 0.0
        cy = 0.0
        for i in range(n):
            cx += ax[i]
            cy += ay[i]
        cx /= n
        cy /= n
        xs[m], ys[m], owner[m] = cx, cy, e
        m += 1
        taken = min(n, PROBE_CORNERS)
        for k in range(taken):
            i = k * n // taken
            j = (i + 1) % n
            xs[m], ys[m], owner[m] = cx + PULL * (ax[i] - cx), cy + PULL * (ay[i] - cy), e
            mx, my = 0.5 * (ax[i] + ax[j]), 0.5 * (ay[i] + ay[j])
            xs[m + 1], ys[m + 1], owner[m + 1] = cx + PULL * (mx - cx), cy + PULL * (my - cy), e
            m += 2
    return xs[:m], ys[:m], owner[:m]


def _seen(film: _Film, tracer, found: _Shapes, pixels, shapes) -> np.ndarray:
    """(entries,) bool: whether every probe of each entry's region (:func:`_probe_points`) sees the entry's emitter as
    the nearest thing along the camera's ray through it.

    g counts an emitter wherever a camera ray meets its shape; f sees it only where nothing is in front.  Where
    something hides part of a shape in a pixel (a wall in front of a ceiling light of the next room, a pillar, the
    emitter's own lamp shade), f - g there is -L_e on the hidden part: the noise the control variate removes where
    the emitter is seen, it adds where it is hidden (issue 57: a building whose lights are behind walls read 0.12x
    Mitsuba's efficiency with every such entry kept, 4x without the variate).  Dropping an entry keeps g unbiased
    (any subset of entries is), so an entry stays only where its probes all see its emitter; a hidden sliver between
    probes keeps a noise in proportion to its area."""
    xs, ys, owner = _probe_points(pixels, shapes, found.poly_x, found.poly_y, found.poly_n, found.ellipses, film.width)
    sx = (2.0 * xs / film.width - 1.0) * film.tan_x  # camera_ray's map (geometry/camera.py) at film point (x, y)
    sy = (1.0 - 2.0 * ys / film.height) * film.tan_y
    d = film.forward + sx[:, None] * film.right + sy[:, None] * film.up
    d /= np.linalg.norm(d, axis=1)[:, None]
    _, kind, index, prim, _, _ = tracer.intersect(np.broadcast_to(film.eye, d.shape), d)
    a = tracer.arrays
    safe = np.maximum(index, 0)
    light = np.full(kind.shape, -1, np.int64)
    on = kind == SPHERE
    light[on] = a.sphere_light[safe[on]]
    on = kind == RECT
    light[on] = a.rect_light[safe[on]]
    on = kind == MESH
    first = a.mesh_light_start[safe[on]]
    light[on] = np.where(first >= 0, first + prim[on], -1)
    wrong = light != found.light[shapes[owner]]
    probed = np.bincount(owner, minlength=pixels.size)
    hidden = np.bincount(owner, weights=wrong, minlength=pixels.size)
    return (probed > 0) & (hidden == 0)


def table(camera, lights, tracer) -> OutlineTable:
    """The outline entries of every area light the camera sees whole from its emitting side (none where two may
    overlap in a pixel, none where something hides the light: :func:`_seen`; the nearer shapes' first where a cap
    binds).  ``tracer``: the scene's :class:`~lightprobe.geometry.raytracer.RayTracer`, or None to keep the entries
    of hidden lights too (the geometry alone, for its tests)."""
    film = _Film(camera)
    width, height = film.width, film.height
    n_pixels = width * height
    found = _shapes(film, lights)
    if found.light.size == 0:
        return empty()
    boxes = np.stack([found.poly_x.min(1), found.poly_x.max(1), found.poly_y.min(1), found.poly_y.max(1)], axis=1)
    pixels, covers, shapes = _entries(
        found.poly_x, found.poly_y, found.poly_n, found.ellipses, width, height, MAX_ENTRIES_PER_PIXEL * n_pixels
    )
    if pixels.size == 0:
        return empty()
    order = np.argsort(pixels, kind="stable")  # each pixel's entries nearest shape first
    pixels, covers, shapes = pixels[order], covers[order], shapes[order]
    start = np.zeros(n_pixels + 1, np.int64)
    np.cumsum(np.bincount(pixels, minlength=n_pixels), out=start[1:])
    # a pixel a shape covers whole has no outline of it (f = g there), but it may hide another
    keep = _separate(start, shapes, width, found.poly_x, found.poly_y, found.poly_n, boxes) & (covers < 1.0)
    pixels, covers, shapes = pixels[keep], covers[keep], shapes[keep]
    if tracer is not None and pixels.size:
        keep = _seen(film, tracer, found, pixels, shapes)
        pixels, covers, shapes = pixels[keep], covers[keep], shapes[keep]
    # at most MAX_PER_PIXEL entries a pixel: its nearest shapes'
    first = np.searchsorted(pixels, pixels, side="left")
    keep = np.arange(pixels.size) - first < MAX_PER_PIXEL
    pixels, covers, shapes = pixels[keep], covers[keep], shapes[keep]
    if pixels.size == 0:
        return empty()
    used, shapes = np.unique(shapes, return_inverse=True)  # the rows of the shapes that kept an entry, in order
    start[:] = 0
    np.cumsum(np.bincount(pixels, minlength=n_pixels), out=start[1:])
    return OutlineTable(
        start,
        np.ascontiguousarray(shapes.astype(np.int64)),
        np.ascontiguousarray(covers),
        np.ascontiguousarray(found.rows[used]),
        np.ascontiguousarray(lights.radiance[found.light[used]].astype(np.float64).reshape(-1, 3)),
    )


def pass_fields(camera, lights, tracer, enabled: bool) -> dict:
    """The outline fields of integrators/pass_state.PassConstants (empty unless ``enabled``)."""
    t = table(camera, lights, tracer) if enabled else empty()
    return {f"outline_{name}": getattr(t, name) for name in OutlineTable._fields}
