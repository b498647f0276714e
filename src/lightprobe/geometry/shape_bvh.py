"""A bounding volume hierarchy over the analytic shapes (spheres and parallelograms), in float64.

A scene with a few spheres and rectangles tests every one for every ray (the loops of
:func:`lightprobe.geometry.intersect.closest_analytic` and the 8-wide lanes of ``integrators/stages/ray_lanes.py``).
A scene file with thousands of rectangle lights would pay for all of them on every camera, BSDF and shadow ray
(about 20x the time of the same quads as one mesh at 2,000, issue 32).  Above :data:`SHAPES_FOR_BVH` shapes the
scene carries this hierarchy and every analytic ray query walks it instead (decisions.md 70 has the measurements).
The shapes stay exact: the tree only culls, each candidate is intersected by the same float64 routines.

Layout: nodes in depth-first order with an *escape* index (a threaded BVH, Smits 1998): node i's subtree is the
range (i, ``skip[i]``), an interior node's children i + 1 and ``skip[i + 1]``.  Boxes are padded by far more than
their float64 rounding, so no ray that meets a shape can miss its box.  Built in compiled code, one shape a leaf,
each split chosen by the surface-area heuristic (:func:`_build_sah`; median splits until decisions.md 106, which
cut a street of lit facades down its middle): 100,000 shapes in well under a second.  Rays walk the same tree
collapsed to eight children a node (``wide_tree.py``; ``boxes``, ``child``, ``parent``): one vector slab test per
node for its eight children (``shape_tree_lanes.py``, whose scalar twin is :func:`box_entered`), where the threaded
walk tested one box at a time (decisions.md 90), nearest child first for a nearest hit (``intersect._next_leaves``).

The few largest shapes (at most ``MAX_LOOSE``, each more than a quarter of the scene's extent: a ground, a dome)
stay out of the tree and are tested first: in it, their boxes would be part of every node above them.

Primitive numbering: p < S is sphere p, p >= S is rectangle p - S (S spheres).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._numba import jit_alloc, jit_inline
from ..errors import ParameterError
from .shape_tree_lanes import BOXES_WIDTH
from .wide_tree import WIDTH, collapse

__all__ = ["LEAF_SIZE", "SHAPES_FOR_BVH", "ShapeTree", "build_shape_tree", "empty_shape_tree"]

#: analytic shapes above which a scene takes the hierarchy (the crossover is about 32 on the environment path and
#: below 6 on the area-light path: decisions.md 70)
SHAPES_FOR_BVH = 16
LEAF_SIZE = 1  # one shape a leaf (_build_sah): 4-11 % faster than two on the suite's tree scenes (decisions.md 90)
MAX_LOOSE = 4  # large shapes kept out of the tree at most
_PAD = 1e-9  # relative to each box's size and coordinates
MAX_WIDE_DEPTH = 8  # levels of the eight-wide tree: a ray's walk keeps a byte per level in one int64
# binary levels below the root at most: a wide node's internal children lie three binary levels below it
# (wide_tree.py), so a leaf at binary depth 21 sits in wide level 7 at most, the deepest of MAX_WIDE_DEPTH
MAX_BINARY_DEPTH = 3 * (MAX_WIDE_DEPTH - 1)
SAH_BINS = 32  # candidate split planes per axis of the surface-area heuristic (Wald 2007's binned build)


class ShapeTree(NamedTuple):
    """The hierarchy's arrays (all empty when the scene tests its shapes one by one)."""

    lo: np.ndarray  # (N, 3) float64 box corners
    hi: np.ndarray  # (N, 3)
    skip: np.ndarray  # (N,) int64: the next node once this one is missed or done
    first: np.ndarray  # (N,) int64: a leaf's first entry in ``prims``
    count: np.ndarray  # (N,) int64: a leaf's number of shapes; 0 for an interior node
    prims: np.ndarray  # (P,) int64: shape numbers in leaf order
    loose: np.ndarray  # (K,) int64: large shapes tested one by one before the tree (a ground, a dome)
    # the same tree eight children a node (geometry/wide_tree.py), which the rays walk (intersect._first_hit):
    boxes: np.ndarray  # (W, 48) float64: the children's boxes (shape_tree_lanes.py), NaN for a missing child
    child: np.ndarray  # (W, 8) int64: a child's wide node (>= 0), -2 - i for the leaf that is node i above, -1: none
    parent: np.ndarray  # (W,) int64: each wide node's parent (-1: the root)


def empty_shape_tree() -> ShapeTree:
    z3 = np.zeros((0, 3))
    zi = np.zeros(0, np.int64)
    return ShapeTree(
        z3, z3.copy(), zi, zi.copy(), zi.copy(), zi.copy(), zi.copy(), np.zeros((0, BOXES_WIDTH)),
        np.zeros((0, WIDTH), np.int64), zi.copy(),
    )  # fmt: skip


def shape_boxes(spheres: np.ndarray, rects: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of every analytic shape, spheres first (rows as in ``SceneArrays``)."""
    c, r = spheres[:, 0:3], spheres[:, 3:4]
    o, u, v = rects[:, 0:3], rects[:, 3:6], rects[:, 6:9]
    corners = np.stack([o, o + u, o + v, o + u + v])
    lo = np.concatenate([c - r, corners.min(axis=0)])
    hi = np.concatenate([c + r, corners.max(axis=0)])
    return np.ascontiguousarray(lo), np.ascontiguousarray(hi)


def build_shape_tree(spheres: np.ndarray, rects: np.ndarray) -> ShapeTree:
    """The hierarchy over ``spheres`` (S, 4) and ``rects`` (R, RECT_WIDTH), or an empty one at or below
    :data:`SHAPES_FOR_BVH` shapes."""
    n = spheres.shape[0] + rects.shape[0]
    if n <= SHAPES_FOR_BVH:
        return empty_shape_tree()
    lo, hi = shape_boxes(spheres, rects)
    pad = _PAD * (np.abs(lo) + np.abs(hi) + (hi - lo).max(axis=1, keepdims=True)) + 1e-300
    # a shape as large as a quarter of the scene (a ground under thousands of small lights) would put its box in
    # every node above it, which nearly every ray then enters: the few largest are tested before the tree instead
    extent = (hi - lo).max(axis=1)
    scene = float((hi.max(axis=0) - lo.min(axis=0)).max())
    large = np.flatnonzero(extent > scene / 4)
    loose = large[np.argsort(-extent[large], kind="stable")][:MAX_LOOSE]
    if loose.size == n:
        loose = loose[:0]
    rest = np.setdiff1d(np.arange(n), loose)
    if rest.size > 1 << MAX_BINARY_DEPTH:
        raise ParameterError(f"too many spheres and rectangles for the shape hierarchy ({rest.size} in it)")
    node_lo, node_hi, skip, first, count, prims = _build_sah(
        lo[rest] - pad[rest], hi[rest] + pad[rest], MAX_BINARY_DEPTH, SAH_BINS
    )
    boxes, child, parent = _eight_wide(node_lo, node_hi, skip, count)
    return ShapeTree(
        node_lo, node_hi, skip, first, count, np.ascontiguousarray(rest[prims]), np.sort(loose), boxes, child, parent
    )


def _eight_wide(node_lo, node_hi, skip, count):
    """The tree eight children a node: (boxes, child, parent) of :class:`ShapeTree`.  An internal node i's children
    are i + 1 and the node after that one's subtree, skip[i + 1]."""
    m = skip.shape[0]
    second = np.where(count == 0, skip[np.minimum(np.arange(m) + 1, m - 1)], -1)
    kids, child, parent, _, deepest = collapse(second, np.arange(1, m + 1))
    if deepest >= MAX_WIDE_DEPTH:
        raise ParameterError(f"too many spheres and rectangles for the shape hierarchy ({count.sum()} in it)")
    lo, hi = node_lo[np.maximum(kids, 0)], node_hi[np.maximum(kids, 0)]  # (W, 8, 3)
    lo[kids < 0] = hi[kids < 0] = np.nan  # a missing child (shape_tree_lanes.py drops NaN boxes)
    boxes = np.concatenate([lo.transpose(0, 2, 1), hi.transpose(0, 2, 1)], axis=1).reshape(-1, BOXES_WIDTH)
    return np.ascontiguousarray(boxes), child, parent


@jit_alloc
def sort_along_widest_axis(centroid, items, start, end):
    """Sort ``items[start:end]`` (rows of ``centroid``) along the axis where their centroids spread the most: the
    median split of the light BVH (emitters/selection.py) and this tree's fallback.  Stable, so the same tree
    everywhere."""
    axis = 0
    widest = -1.0
    for a in range(3):
        c_lo, c_hi = np.inf, -np.inf
        for j in range(start, end):
            c_lo = min(c_lo, centroid[items[j], a])
            c_hi = max(c_hi, centroid[items[j], a])
        if c_hi - c_lo > widest:
            widest, axis = c_hi - c_lo, a
    keys = np.empty(end - start)
    for j in range(start, end):
        keys[j - start] = centroid[items[j], axis]
    # a merge sort of its own, bottom-up, the left run first among equal keys: np.argsort's stable sort, whose
    # implementation took a second to compile (decisions.md 130); written back element by element, not by a slice
    # assignment, which compiles Numba's shape-mismatch message (1.7 s)
    n = end - start
    src = items[start:end].copy()
    dst = np.empty_like(src)
    src_keys = keys
    dst_keys = np.empty(n)
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid, hi = min(lo + width, n), min(lo + 2 * width, n)
            i, j = lo, mid
            for k in range(lo, hi):
                if i < mid and (j >= hi or src_keys[i] <= src_keys[j]):
                    dst[k], dst_keys[k] = src[i], src_keys[i]
                    i += 1
                else:
                    dst[k], dst_keys[k] = src[j], src_keys[j]
                    j += 1
        src, dst = dst, src
        src_keys, dst_keys = dst_keys, src_keys
        width *= 2
    for j in range(n):
        items[start + j] = src[j]


@jit_inline
def box_entered(ox, oy, oz, ix, iy, iz, lo, hi, i, tmax):
    """Whether the segment [0, tmax] of the ray (o, 1/d = (ix, iy, iz)) meets box i of (lo, hi).  Infinite
    reciprocals (d_a = 0) give +-inf slabs, or NaN on a face (o_a = lo_a), which min/max below drop, as the padded
    boxes allow."""
    a0 = (lo[i, 0] - ox) * ix
    b0 = (hi[i, 0] - ox) * ix
    a1 = (lo[i, 1] - oy) * iy
    b1 = (hi[i, 1] - oy) * iy
    a2 = (lo[i, 2] - oz) * iz
    b2 = (hi[i, 2] - oz) * iz
    near = max(0.0, min(a0, b0), min(a1, b1), min(a2, b2))
    far = min(tmax, max(a0, b0), max(a1, b1), max(a2, b2))
    return near <= far


@jit_inline
def _bin(x, lo, extent, bins):
    """The bin, of ``bins`` equal ones over [lo, lo + extent], that holds centroid coordinate x: the same expression
    where the build counts a node's shapes and where it partitions them."""
    return min(int(bins * ((x - lo) / extent)), bins - 1)


@jit_inline
def push_halves(stack, top, node, start, end, half, depth):
    """Push a node's two halves on a depth-first build's stack of (node, start, end, depth) rows, the first
    ``half`` items on top (popped first: its subtree takes the slots right after ``node``, 2 half - 1 of them, so
    the second half's node is node + 2 half); returns the new top.  This tree and the light BVH
    (emitters/selection.py) both number their nodes so."""
    stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = node + 2 * half, start + half, end, depth + 1
    stack[top + 1, 0], stack[top + 1, 1], stack[top + 1, 2], stack[top + 1, 3] = (
        node + 1,
        start,
        start + half,
        depth + 1,
    )
    return top + 2


@jit_inline
def _area(lo_x, lo_y, lo_z, hi_x, hi_y, hi_z):
    """Half the surface area of a box: a ray's chance of entering it, up to a factor shared by all boxes."""
    x, y, z = hi_x - lo_x, hi_y - lo_y, hi_z - lo_z
    return x * y + y * z + z * x


@jit_alloc
def _build_sah(lo, hi, max_depth, bins):
    """The tree of one shape a leaf, each split chosen by the surface-area heuristic (MacDonald and Booth 1990;
    binned as Wald 2007): of ``bins`` - 1 planes on each axis between the centroids' extremes, the one that
    minimises area(left) x shapes(left) + area(right) x shapes(right), the expected number of shapes a ray through
    the node tests below it.  Median splits cut a street of lit facades through the middle of a facade and give two
    children whose boxes both span the street; the heuristic puts the empty space between boxes.  A split must
    leave each side at most 2^(levels left) shapes so that no leaf is deeper than ``max_depth``; when none of the
    planes does (or every centroid coincides), the node splits at the median along the widest axis instead.
    Deterministic: a stable partition, ties to the lower axis and plane.  Returns (node_lo, node_hi, skip, first,
    count, prims) of :class:`ShapeTree`, depth first: any binary tree of n leaves has 2n - 1 nodes, so a node's
    subtree of k shapes takes 2k - 1 slots wherever its splits fall."""
    n = lo.shape[0]
    m = 2 * n - 1
    node_lo = np.empty((m, 3))
    node_hi = np.empty((m, 3))
    skip = np.empty(m, np.int64)
    first = np.zeros(m, np.int64)
    count = np.zeros(m, np.int64)
    prims = np.arange(n)
    scratch = np.empty(n, np.int64)
    centroid = 0.5 * (lo + hi)
    bin_lo = np.empty((bins, 3))
    bin_hi = np.empty((bins, 3))
    bin_n = np.empty(bins, np.int64)
    right_area = np.empty(bins)
    right_n = np.empty(bins, np.int64)
    c_lo = np.empty(3)
    c_hi = np.empty(3)
    stack = np.empty((2 * max_depth + 2, 4), np.int64)  # node, start, end, depth
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, 0, n, 0
    top = 1
    while top > 0:
        top -= 1
        node, start, end, depth = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        for a in range(3):
            node_lo[node, a], node_hi[node, a] = np.inf, -np.inf
            c_lo[a], c_hi[a] = np.inf, -np.inf
        for j in range(start, end):
            p = prims[j]
            for a in range(3):
                node_lo[node, a] = min(node_lo[node, a], lo[p, a])
                node_hi[node, a] = max(node_hi[node, a], hi[p, a])
                c_lo[a] = min(c_lo[a], centroid[p, a])
                c_hi[a] = max(c_hi[a], centroid[p, a])
        size = end - start
        skip[node] = node + 2 * size - 1
        if size == 1:
            first[node], count[node] = start, 1
            continue
        cap = 1 << (max_depth - depth - 1)  # the most shapes a child's subtree of max_depth - depth - 1 levels holds
        best_cost, best_axis, best_plane = np.inf, -1, -1
        for a in range(3):
            extent = c_hi[a] - c_lo[a]
            if not extent > 0.0:
                continue
            for b in range(bins):
                bin_n[b] = 0
                for k in range(3):
                    bin_lo[b, k], bin_hi[b, k] = np.inf, -np.inf
            for j in range(start, end):
                p = prims[j]
                b = _bin(centroid[p, a], c_lo[a], extent, bins)
                bin_n[b] += 1
                for k in range(3):
                    bin_lo[b, k] = min(bin_lo[b, k], lo[p, k])
                    bin_hi[b, k] = max(bin_hi[b, k], hi[p, k])
            # sweep from the right: the box and count of bins b .. bins - 1
            rx0, ry0, rz0, rx1, ry1, rz1, rn = np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf, 0
            for b in range(bins - 1, 0, -1):
                rx0, ry0, rz0 = min(rx0, bin_lo[b, 0]), min(ry0, bin_lo[b, 1]), min(rz0, bin_lo[b, 2])
                rx1, ry1, rz1 = max(rx1, bin_hi[b, 0]), max(ry1, bin_hi[b, 1]), max(rz1, bin_hi[b, 2])
                rn += bin_n[b]
                right_n[b] = rn
                right_area[b] = _area(rx0, ry0, rz0, rx1, ry1, rz1) if rn > 0 else 0.0
            # sweep from the left: the plane after bin b splits bins 0 .. b from b + 1 .. bins - 1
            lx0, ly0, lz0, lx1, ly1, lz1, ln = np.inf, np.inf, np.inf, -np.inf, -np.inf, -np.inf, 0
            for b in range(bins - 1):
                lx0, ly0, lz0 = min(lx0, bin_lo[b, 0]), min(ly0, bin_lo[b, 1]), min(lz0, bin_lo[b, 2])
                lx1, ly1, lz1 = max(lx1, bin_hi[b, 0]), max(ly1, bin_hi[b, 1]), max(lz1, bin_hi[b, 2])
                ln += bin_n[b]
                rn = right_n[b + 1]
                if ln == 0 or rn == 0 or ln > cap or rn > cap:
                    continue
                cost = _area(lx0, ly0, lz0, lx1, ly1, lz1) * ln + right_area[b + 1] * rn
                if cost < best_cost:
                    best_cost, best_axis, best_plane = cost, a, b
        if best_axis < 0:  # no plane separates the centroids within the depth allowed: the median
            sort_along_widest_axis(centroid, prims, start, end)
            half = size // 2
        else:
            a = best_axis
            extent = c_hi[a] - c_lo[a]
            half = 0
            for j in range(start, end):  # a stable partition: the left side's shapes first, each side in order
                p = prims[j]
                if _bin(centroid[p, a], c_lo[a], extent, bins) <= best_plane:
                    scratch[start + half] = p
                    half += 1
            right = start + half
            for j in range(start, end):
                p = prims[j]
                if _bin(centroid[p, a], c_lo[a], extent, bins) > best_plane:
                    scratch[right] = p
                    right += 1
            for j in range(start, end):  # not a slice assignment: see sort_along_widest_axis
                prims[j] = scratch[j]
        top = push_halves(stack, top, node, start, end, half, depth)
    return node_lo, node_hi, skip, first, count, prims
