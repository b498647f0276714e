"""The analytic shapes' hierarchy (geometry/shape_bvh.py): every nearest hit and every occlusion the same as testing
each shape in turn, for random rays through thousands of spheres and parallelograms (with a ground and a large
sphere kept out of the tree, or not); the tree covers each shape once and its boxes hold their shapes."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from lightprobe.geometry.intersect import rectangle_rows
from lightprobe.geometry.raytracer import _closest_analytic_batch, _occluded_analytic_batch
from lightprobe.geometry.scene_arrays import SceneArrays
from lightprobe.geometry.shape_bvh import (
    LEAF_SIZE,
    MAX_BINARY_DEPTH,
    SHAPES_FOR_BVH,
    box_entered,
    build_shape_tree,
    empty_shape_tree,
    shape_boxes,
    sort_along_widest_axis,
)
from lightprobe.geometry.shape_tree_lanes import boxes_entered, nearest_boxes
from lightprobe.geometry.wide_tree import collapse


def _shapes(n_spheres, n_rects, seed, large=False):
    """Small spheres and slanted parallelograms (oblique edges) scattered in a 10-unit box, some overlapping; with
    ``large``, a 40-unit ground and a sphere of radius 8 too (tested before the tree)."""
    rng = np.random.default_rng(seed)
    spheres = np.column_stack([rng.uniform(-5, 5, (n_spheres, 3)), rng.uniform(0.02, 0.3, n_spheres)])
    origin = rng.uniform(-5, 5, (n_rects, 3))
    u = rng.normal(size=(n_rects, 3)) * 0.3
    v = rng.normal(size=(n_rects, 3)) * 0.3
    if large:
        spheres = np.concatenate([spheres, [[2.0, -12.0, 1.0, 8.0]]])
        origin, u, v = (
            np.concatenate([a, [b]]) for a, b in ((origin, [-20, -6, -20]), (u, [0, 0, 40]), (v, [40, 0, 0]))
        )
    return np.ascontiguousarray(spheres), rectangle_rows(origin, u, v)


def _arrays(spheres, rects, tree):
    """SceneArrays with these shapes (no meshes, no materials) and ``tree``'s arrays."""
    empty3 = np.zeros((0, 3))
    emptyi = np.zeros(0, np.int64)
    return SceneArrays(
        empty3,
        empty3,
        np.zeros((0, 3), np.int64),
        np.zeros(1, np.int64),
        emptyi,
        emptyi,
        emptyi,
        np.zeros((0, 2, 3)),
        np.zeros((0, 5)),
        spheres,
        np.zeros(spheres.shape[0], np.int64),
        np.zeros(spheres.shape[0], np.int64),
        rects,
        np.zeros(rects.shape[0], np.int64),
        np.zeros(rects.shape[0], np.int64),
        np.full(spheres.shape[0], -1, np.int64),
        np.full(rects.shape[0], -1, np.int64),
        emptyi,
        emptyi,
        np.zeros((0, 16)),
        emptyi,
        np.zeros((0, 3), np.int64),
        np.zeros(0),
        np.zeros((0, 2)),
        np.zeros((0, 2)),
        np.zeros((0, 4)),
        np.zeros((0, 7), np.int64),
        np.zeros((0, 4), np.uint8),
        np.zeros((0, 4), np.float32),
        *tree,
    )


def _trace(s, origins, dirs, tmax):
    """Nearest hits (unbounded) and occlusion of the segments (0, tmax), through the ray tracer's batch kernels."""
    t, kind, index, _ = _closest_analytic_batch(s, origins, dirs)
    blocked, _ = _occluded_analytic_batch(s, origins, dirs, tmax)
    return t, kind, index, blocked


def _rays(n, seed):
    """Rays from inside and outside the shapes' box, random and axis-aligned directions (zero components: the slab
    test's 1 / 0), unbounded and short segments."""
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-8, 8, (n, 3))
    dirs = rng.normal(size=(n, 3))
    dirs[::5] = np.eye(3)[rng.integers(0, 3, dirs[::5].shape[0])] * rng.choice([-1.0, 1.0], (dirs[::5].shape[0], 1))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    tmax = np.where(rng.random(n) < 0.5, np.inf, rng.uniform(0.1, 6.0, n))
    return origins, dirs, tmax


@pytest.mark.parametrize(
    ("n_spheres", "n_rects", "large"), [(300, 2000, True), (0, 1500, False), (1200, 0, True), (10, 7, False)]
)
def test_the_tree_finds_what_testing_every_shape_finds(n_spheres, n_rects, large):
    spheres, rects = _shapes(n_spheres, n_rects, seed=n_spheres + n_rects, large=large)
    tree = build_shape_tree(spheres, rects)
    assert (tree.skip.shape[0] > 0) == (spheres.shape[0] + rects.shape[0] > SHAPES_FOR_BVH)
    assert tree.loose.size == (2 if large else 0)
    origins, dirs, tmax = _rays(10_000, seed=7)
    flat = _trace(_arrays(spheres, rects, empty_shape_tree()), origins, dirs, tmax)
    walked = _trace(_arrays(spheres, rects, tree), origins, dirs, tmax)
    for a, b in zip(flat, walked, strict=True):
        np.testing.assert_array_equal(a, b)
    hit = np.isfinite(flat[0])
    assert 10 < hit.sum() < 0.98 * hit.size  # rays that hit and rays that miss, both
    assert np.array_equal(flat[3], flat[0] < tmax)  # blocked: the nearest hit lies within the segment


def test_the_tree_holds_each_shape_once_in_boxes_that_contain_it():
    spheres, rects = _shapes(500, 3000, seed=3, large=True)
    tree = build_shape_tree(spheres, rects)
    n = spheres.shape[0] + rects.shape[0]
    assert np.array_equal(np.sort(np.concatenate([tree.prims, tree.loose])), np.arange(n))
    np.testing.assert_array_equal(tree.loose, [500, n - 1])  # the large sphere and the ground
    leaves = np.flatnonzero(tree.count > 0)
    assert tree.count[leaves].sum() == n - 2 and tree.count.max() <= LEAF_SIZE
    lo, hi = shape_boxes(spheres, rects)
    for leaf in leaves:
        members = tree.prims[tree.first[leaf] : tree.first[leaf] + tree.count[leaf]]
        assert np.all(tree.lo[leaf] <= lo[members]) and np.all(hi[members] <= tree.hi[leaf])
    # depth-first order: a node's subtree is the range (node, skip[node]), inside its parent's, and every node's box
    # holds the boxes of its subtree
    for node in range(tree.skip.shape[0]):
        inner = slice(node + 1, tree.skip[node])
        assert tree.skip[node] <= tree.skip.shape[0]
        assert np.all(tree.lo[inner] >= tree.lo[node]) and np.all(tree.hi[inner] <= tree.hi[node])
    assert tree.skip[0] == tree.skip.shape[0]  # the root's subtree is the whole tree


@njit
def _masks(boxes, origins, inverse, tmax, out):
    for i in range(origins.shape[0]):
        o, inv = origins[i], inverse[i]
        for node in range(boxes.shape[0]):
            out[i, node] = boxes_entered(boxes, node, o[0], o[1], o[2], inv[0], inv[1], inv[2], tmax[i])


@njit
def _scalar_masks(lo, hi, kids, origins, inverse, tmax, out):
    for i in range(origins.shape[0]):
        o, inv = origins[i], inverse[i]
        for node in range(kids.shape[0]):
            bits = 0
            for c in range(8):
                if kids[node, c] >= 0 and box_entered(
                    o[0], o[1], o[2], inv[0], inv[1], inv[2], lo, hi, kids[node, c], tmax[i]
                ):
                    bits |= 1 << c
            out[i, node] = bits


def test_the_eight_wide_walk_tests_the_binary_trees_boxes():
    """The tree the rays walk is the binary tree eight children a node: each wide node's children are binary nodes
    (every leaf once), their boxes the binary boxes, and the vector slab test enters exactly the children the scalar
    ``box_entered`` enters (axis-aligned rays: 1 / 0 slabs), never a missing one (a NaN box)."""
    spheres, rects = _shapes(200, 1500, seed=5, large=True)
    tree = build_shape_tree(spheres, rects)
    m = tree.skip.shape[0]
    second = np.where(tree.count == 0, tree.skip[np.minimum(np.arange(m) + 1, m - 1)], -1)
    kids, child, parent, _, _ = collapse(second, np.arange(1, m + 1))
    np.testing.assert_array_equal(child, tree.child)
    np.testing.assert_array_equal(parent, tree.parent)
    leaves = -2 - child[child <= -2]
    assert np.array_equal(np.sort(leaves), np.flatnonzero(tree.count > 0))
    present = kids >= 0
    assert np.all(present.sum(axis=1) >= 2) and np.all(
        np.isnan(tree.boxes.reshape(-1, 6, 8).transpose(0, 2, 1)[~present])
    )
    origins, dirs, tmax = _rays(300, seed=11)
    with np.errstate(divide="ignore"):
        inverse = 1.0 / dirs
    vector = np.empty((300, child.shape[0]), np.int64)
    scalar = np.empty_like(vector)
    _masks(tree.boxes, origins, inverse, tmax, vector)
    _scalar_masks(tree.lo, tree.hi, kids, origins, inverse, tmax, scalar)
    np.testing.assert_array_equal(vector, scalar)
    assert np.count_nonzero(vector) > 500 and np.count_nonzero(vector & (vector - 1)) > 100  # some with several


@njit
def _nearest(boxes, children, origins, inverse, tmax, among, out):
    for i in range(origins.shape[0]):
        o, inv = origins[i], inverse[i]
        for node in range(boxes.shape[0]):
            out[i, node] = nearest_boxes(
                boxes, node, o[0], o[1], o[2], inv[0], inv[1], inv[2], tmax[i], among[i, node], children
            )


def test_the_nearest_first_test_picks_the_box_the_segment_enters_first():
    """``nearest_boxes``: of the children asked about, those entered (as the scalar slab test), the first entered
    (the least entry distance, ties all set), and the leaves among them."""
    spheres, rects = _shapes(200, 1500, seed=5, large=True)
    tree = build_shape_tree(spheres, rects)
    m = tree.skip.shape[0]
    second = np.where(tree.count == 0, tree.skip[np.minimum(np.arange(m) + 1, m - 1)], -1)
    kids, _, _, _, _ = collapse(second, np.arange(1, m + 1))
    origins, dirs, tmax = _rays(300, seed=13)
    with np.errstate(divide="ignore"):
        inverse = 1.0 / dirs
    among = np.random.default_rng(2).integers(0, 256, (300, kids.shape[0]))
    among[::3] = 255
    found = np.empty((300, kids.shape[0]), np.int64)
    _nearest(tree.boxes, tree.child, origins, inverse, tmax, among, found)
    scalar = np.empty_like(found)
    _scalar_masks(tree.lo, tree.hi, kids, origins, inverse, tmax, scalar)
    entered = scalar & among
    np.testing.assert_array_equal((found >> 8) & 255, entered)
    np.testing.assert_array_equal(
        (found >> 16) & 255, entered & np.packbits(tree.child < -1, axis=1, bitorder="little")[:, 0]
    )
    lo = tree.lo[np.maximum(kids, 0)]  # (W, 8, 3)
    hi = tree.hi[np.maximum(kids, 0)]
    checked = 0
    for i in range(300):
        with np.errstate(invalid="ignore"):
            t0 = (lo - origins[i]) * inverse[i]
            t1 = (hi - origins[i]) * inverse[i]
        near = np.maximum(0.0, np.nan_to_num(np.minimum(t0, t1), nan=-np.inf).max(axis=2))
        for node in np.flatnonzero(entered[i]):
            slots = [c for c in range(8) if entered[i, node] >> c & 1]
            least = min(near[node, c] for c in slots)
            expected = sum(1 << c for c in slots if near[node, c] == least)
            assert found[i, node] & 255 == expected
            checked += len(slots) > 1
    assert checked > 100  # nodes where the choice was between several children


def test_surface_area_splits_put_the_empty_space_between_the_children():
    """Two rows of rectangles with a gap between them, 100 on the left and 300 on the right: the median split along
    x cuts the right row, so both children would span the gap; the surface-area heuristic splits at the gap."""
    x = np.concatenate([np.linspace(0.0, 1.0, 100), np.linspace(3.0, 4.0, 300)])
    origin = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    rects = rectangle_rows(origin, np.tile([0.002, 0.0, 0.0], (400, 1)), np.tile([0.0, 0.0, 0.01], (400, 1)))
    tree = build_shape_tree(np.zeros((0, 4)), rects)
    left, right = 1, tree.skip[1]
    assert tree.hi[left, 0] < 1.01 and tree.lo[right, 0] > 2.99


def test_a_clustered_scene_keeps_the_wide_tree_within_its_depth():
    """Shapes at x = 1.2^k: each surface-area split would peel off the farthest few, a chain far deeper than the eight
    wide levels a ray's walk can hold; below that depth the build splits at the median, and the walk still finds
    every hit."""
    n = 3000
    x = 1.2 ** (np.arange(n) % 200) + np.arange(n) * 1e-3
    origin = np.column_stack([x, np.arange(n) % 7 * 0.1, np.zeros(n)])
    rects = rectangle_rows(origin, np.tile([0.01, 0.0, 0.0], (n, 1)), np.tile([0.0, 0.05, 0.05], (n, 1)))
    tree = build_shape_tree(np.zeros((0, 4)), rects)
    depth = np.zeros(tree.skip.shape[0], np.int64)
    for node in range(tree.skip.shape[0]):
        if tree.count[node] == 0:
            depth[node + 1] = depth[tree.skip[node + 1]] = depth[node] + 1
    assert depth.max() == MAX_BINARY_DEPTH  # the heuristic went as deep as it may, not deeper
    rng = np.random.default_rng(4)
    targets = origin[rng.integers(0, n, 3000)] + [0.005, 0.025, 0.025]  # rays aimed at shapes, hitting them or others
    origins = targets + rng.normal(size=(3000, 3)) * rng.choice([0.5, 5.0, 50.0], (3000, 1))
    dirs = targets - origins
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    tmax = np.full(3000, np.inf)
    flat = _trace(_arrays(np.zeros((0, 4)), rects, empty_shape_tree()), origins, dirs, tmax)
    walked = _trace(_arrays(np.zeros((0, 4)), rects, tree), origins, dirs, tmax)
    for a, b in zip(flat, walked, strict=True):
        np.testing.assert_array_equal(a, b)
    assert np.isfinite(flat[0]).sum() > 2500


def test_the_widest_axis_sort_is_numpys_stable_sort():
    # its own merge sort (not np.argsort's, a second of compiling): the same order, ties in their former order,
    # only items[start:end] touched
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 5, 8, 17, 100, 1000):
        for ties in (False, True):
            centroid = rng.integers(0, 4, (n, 3)).astype(np.float64) if ties else rng.uniform(-1, 1, (n, 3))
            items = rng.permutation(n).astype(np.int64)
            padded = np.concatenate([[-1, -2], items, [-3]]).astype(np.int64)
            spread = centroid[items].max(axis=0) - centroid[items].min(axis=0)
            axis = int(np.argmax(spread))  # the first of equal spreads, as the kernel's strict comparison
            expected = padded.copy()
            expected[2 : 2 + n] = items[np.argsort(centroid[items, axis], kind="stable")]
            sort_along_widest_axis(centroid, padded, 2, 2 + n)
            assert np.array_equal(padded, expected), (n, ties)
