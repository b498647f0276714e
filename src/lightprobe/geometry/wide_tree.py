"""Eight children a node: the collapse of a binary tree that the light BVH and the shape hierarchy share.

Both trees are built binary (a split is a choice between two sides) and walked eight-wide, where one vector of
eight lanes tests or weighs a node's children at once (``emitters/light_tree_lanes.py``,
``geometry/shape_tree_lanes.py``).  A wide node's children are its binary node's descendants: each internal one
replaced by its two children, the shallowest first, while there are fewer than eight, in the binary tree's left to
right order.  So a wide node's descendants one and two binary levels down (at most 2 + 4) are always replaced, and
each of its internal children lies at least three binary levels below it: a binary tree of depth D gives at most
ceil(D / 3) wide levels (decisions.md 90).
"""

from __future__ import annotations

import numpy as np

from .._numba import jit_alloc
from ..simd import LANES

__all__ = ["PATH_BITS", "WIDTH", "collapse"]

WIDTH = LANES  # children per wide node: a vector's lanes
PATH_BITS = 3  # bits of a leaf's path per level: its slot, 0 .. WIDTH - 1


@jit_alloc
def collapse(second, first_child):
    """The eight-wide tree of a binary one whose internal node i has children ``first_child[i]`` and ``second[i]``
    (``second[i] < 0``: i is a leaf); node 0 the root.  Returns

    * ``kids`` (W, 8): each wide node's children as binary nodes, -1 where it has fewer than eight;
    * ``child`` (W, 8): a child's wide node (>= 0), ``-2 - b`` for a binary leaf b, -1 for none;
    * ``parent`` (W,): each wide node's parent (-1 for the root);
    * ``path`` (binary nodes,): for each binary leaf, its child slots from the root, three bits a level (bits
      3d .. 3d + 2: the slot at depth d);
    * the deepest wide level (the root's is 0).

    Wide nodes are numbered in depth-first order, a parent before its children."""
    m = second.shape[0]
    cap = max(1, (m - 1) // 2)  # each wide node is an internal binary node (or a one-leaf root)
    kids_of = np.full((cap, WIDTH), -1, np.int64)
    child = np.full((cap, WIDTH), -1, np.int64)
    parent = np.full(cap, -1, np.int64)
    path = np.zeros(m, np.int64)
    stack = np.empty((cap, 4), np.int64)  # binary node, wide node, path, depth
    kids = np.empty(WIDTH, np.int64)
    level = np.empty(WIDTH, np.int64)
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, 0, 0, 0
    top, count, deepest = 1, 1, 0
    while top > 0:
        top -= 1
        binary, wide, bits, depth = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        deepest = max(deepest, depth)
        if second[binary] < 0:  # a tree of one leaf
            kids[0], level[0], n = binary, 0, 1
        else:
            kids[0], kids[1], level[0], level[1], n = first_child[binary], second[binary], 1, 1, 2
        while n < WIDTH:
            best = -1  # the shallowest internal child, the first of equals
            for c in range(n):
                if second[kids[c]] >= 0 and (best < 0 or level[c] < level[best]):
                    best = c
            if best < 0:
                break
            node, below = kids[best], level[best] + 1
            for c in range(n - 1, best, -1):
                kids[c + 1], level[c + 1] = kids[c], level[c]
            kids[best], kids[best + 1] = first_child[node], second[node]
            level[best] = level[best + 1] = below
            n += 1
        for c in range(n):
            kid = kids[c]
            kids_of[wide, c] = kid
            slots = bits | (c << (PATH_BITS * depth))
            if second[kid] < 0:
                child[wide, c] = -2 - kid
                path[kid] = slots
            else:
                child[wide, c] = count
                parent[count] = wide
                stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = kid, count, slots, depth + 1
                top += 1
                count += 1
    return kids_of[:count].copy(), child[:count].copy(), parent[:count].copy(), path, deepest
