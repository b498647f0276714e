"""Light selection that learns what reaches the receivers, shadows included (issue 59; decision 114).

Every selector picks a light by what it would give if nothing were in the way (``selection.py``: the light BVH's
importance of a node is pi x a bound on its lights' unoccluded irradiance).  In a building whose lights are mostly
in other rooms most of those picks end in a blocked shadow ray.  Vevoda, Kondapaneni and Krivanek 2018 ("Bayesian
online regression for adaptive direct illumination sampling") learn, per region of shading points, what each group
of lights actually gives, visibility included, from the render's own shadow rays.  This is a simple form of it that
keeps what the BVH knows about each point (distance, orientation) and learns only what it cannot know:

* **Records.** Each light sample of the pilot (the first half of the adaptive pilot, or the first 4 samples of a
  uniform render from sample 0: ``integrators/light_learning.py``) is kept (``Records``: its shading point and
  normal, its light, and lum(f L cos) / the density of the point on the light, negated where the shadow ray was
  blocked): a quarter of the pilot's, but no fewer than ``MIN_RECORDS`` and no more than ``MAX_RECORDS``.
* **Cells.** A k-d tree over the records' points (median splits, leaves of at most ``LEAF_RECORDS`` records):
  cells follow where the visible points are (a uniform grid and image tiles measured against it: decisions.md 127).
* **Ratios.** For every child of the light tree's nodes in the top ``cut_levels`` levels (at most ``MAX_ENTRIES``
  children), each cell learns rho = RMS(v) / mean(w) over the records whose light's path went through the child:
  v = the record's value / the probability of its light below the child, an unbiased estimate of the child's
  contribution at that point (0 behind a wall), w the child's importance there.  The root-mean-square, not the
  mean, because a one-sample estimate's variance is least with probabilities in proportion to the square root of
  each choice's second moment (a light seen from half a cell is not to be halved).  A child with few records is
  pulled toward its parent's ratio (rho = (n rho_hat + TAU rho_parent) / (n + TAU)), one never sampled takes it.
* **The descent.** In a learned cell each child above the cut is chosen with probability
  ``alpha w_c / sum w + (1 - alpha) w_c rho_c / sum w rho`` (``selection._share``), w the BVH's importances
  at the receiver; below the cut, as the BVH.  The probability of every light is the product along its path
  (``selection._path_pmf``), exact for MIS.  Every child the BVH can pick keeps at least alpha (``DEFENSIVE``) of
  its BVH share, so the render stays unbiased whatever was learned.
* **Only where it pays.** A scene whose pilot lost less than ``MIN_BLOCKED`` of what its light samples would have
  given to blocked shadow rays learns nothing (the records hold that loss as negative values).  A cell keeps its
  ratios only if its own records say they lower the second moment of the estimate to ``MARGIN`` of the BVH's (the
  records were drawn from the BVH, so E_q[(c / q)^2] = E_bvh[c^2 / (q p)]); a scene where no cell does keeps no
  cells at all.  Where nothing is hidden the learned ratios only add noise to the BVH's right answer (decision
  114: the dome's error 0.00026 -> 0.00029 without this check, the same with it).

Determinism: the pilot's records sit at positions given by (pixel, sample index, light slot), whatever pass wrote
them (``integrators/light_learning.py``), the tree and the sums read them in that order, and the learned selector
is used from the first sample after the pilot: the image is a pure function of (seed, settings), for any pass size
or thread count.
"""

from __future__ import annotations

import numpy as np

from .._numba import jit, jit_alloc
from .._worksharing import in_threads
from .selection import TRAIL_BITS, WIDTH, LightSelector, _child_weights, _path_pmf, leaf_of

__all__ = [
    "DEFENSIVE",
    "LEAF_RECORDS",
    "MARGIN",
    "MAX_ENTRIES",
    "MAX_RECORDS",
    "MIN_BLOCKED",
    "MIN_RECORDS",
    "TAU",
    "Records",
    "learned",
    "with_cut",
]

MAX_ENTRIES = 1024  # learned children per cell at most: the cut is the deepest level that keeps within it
LEAF_RECORDS = 2048  # light samples per cell at most
MAX_RECORDS = 1 << 21  # the pilot's light samples kept for learning at most (32 bytes each) ...
MIN_RECORDS = 1 << 18  # ... and at least (a quarter of the pilot's between: decision 114)
TREE_POINTS = 1 << 16  # the cells' tree is built from at most about this many of them
DEFENSIVE = 0.2  # alpha, the BVH's share at a learned node
TAU = 4.0  # samples' worth of the parent's ratio in a child's
MARGIN = 0.5  # a cell keeps what it learned where that halves its records' second moment (decision 114)
MIN_BLOCKED = 0.05  # learn nothing where shadows took less than this share of what the pilot's samples would give


def with_cut(sel: LightSelector, max_entries: int = MAX_ENTRIES) -> LightSelector:
    """``sel`` (a light BVH) with its cut: the deepest number of levels whose nodes have at most ``max_entries``
    children in all, and each such node's first entry in a cell's row.  Picks and pmfs are unchanged (no cell is
    learned yet)."""
    child = sel.wide_child
    if child.shape[0] == 0:
        raise ValueError("learned selection needs a light BVH")
    depth = np.full(child.shape[0], -1, np.int64)
    level, nodes = 0, np.zeros(1, np.int64)
    while nodes.size:  # a level of the tree at a time, from the root (every node has one parent)
        depth[nodes] = level
        kids = child[nodes].ravel()
        level, nodes = level + 1, kids[kids >= 0]
    cut = 1
    while np.count_nonzero(depth < cut + 1) * WIDTH <= max_entries and np.any(depth == cut):
        cut += 1
    above = np.flatnonzero(depth < cut)
    offset = np.full(child.shape[0], -1, np.int64)
    offset[above] = np.arange(above.size) * WIDTH
    return sel._replace(cut_levels=cut, learn_offset=offset)


class Records:
    """The pilot's light samples kept for learning, each at a position set by (pixel, sample index, light slot):
    ``samples`` first samples of every ``stride``-th pixel, ``slots`` light slots each.  ``light`` -1: no sample
    there (a camera ray that met no surface, a slot that picked no bounded light, a sample not rendered)."""

    def __init__(self, pixels: int, pilot: int, slots: int, limit: int | None = None, stride: int | None = None):
        self.slots = max(1, slots)
        if stride is not None:  # the pixels a render samples are every stride-th (integrators/picks.py's probe)
            self.samples, self.stride = max(1, pilot), stride
        else:
            if limit is None:  # a quarter of the pilot's light samples: learning costs a few percent of the pilot
                limit = min(MAX_RECORDS, max(MIN_RECORDS, pixels * pilot * max(1, slots) // 4))
            self.samples = max(1, min(pilot, limit // max(1, pixels * self.slots)))
            self.stride = max(1, -(-pixels * self.slots * self.samples // limit))
        n = -(-pixels // self.stride) * self.slots * self.samples
        self.point = np.zeros((n, 3), np.float32)
        self.normal = np.zeros((n, 3), np.float32)
        self.light = np.full(n, -1, np.int32)
        self.value = np.zeros(n, np.float32)  # lum(f L cos) / the density of the point on the light; < 0: blocked


def learned(
    sel: LightSelector,
    records: Records,
    leaf: int = LEAF_RECORDS,
    alpha: float = DEFENSIVE,
    tau: float = TAU,
    margin: float = MARGIN,
) -> LightSelector:
    """``sel`` (:func:`with_cut`) with cells and their ratios learned from ``records``, kept in the cells where
    they lower the records' second moment to ``margin`` of the BVH's (all cells: ``margin`` 0)."""
    kept = np.flatnonzero(records.light >= 0)
    would_give = records.value[kept].astype(np.float64)
    if not -would_give[would_give < 0.0].sum() > MIN_BLOCKED * np.abs(would_give).sum():
        return sel  # (almost) nothing was blocked (or no record at all): nothing the BVH does not know
    points = records.point[kept]
    step = max(1, kept.size // TREE_POINTS)  # the tree's splits from every step-th record: as many cells
    axis, split, nxt = _kd_tree(np.ascontiguousarray(points[::step]), max(1, leaf // step))
    cells = int(nxt[axis < 0, 0].max()) + 1
    entries = int(np.count_nonzero(sel.learn_offset >= 0)) * WIDTH
    normals, light, value = records.normal[kept], records.light[kept], records.value[kept]
    cell, entry, v, weight, p_bvh = _record_terms(sel, axis, split, nxt, points, normals, light, value)
    squares, importance, counts = _add_terms(cell, entry, v, weight, cells, entries)
    ratio = _shrunk(sel, np.sqrt(squares * counts), importance, counts, tau)
    leaves = np.flatnonzero(axis < 0)
    seen = ratio[nxt[leaves, 0]].max(axis=1) > 0.0
    nxt[leaves[~seen], 0] = -1  # nothing arrived there: the BVH alone
    out = sel._replace(cell_axis=axis, cell_split=split, cell_next=nxt, cell_ratio=ratio, defensive=float(alpha))
    if margin > 0.0:
        # keep a cell's learning only where the records say it lowers the second moment of the estimate by
        # ``margin`` (the records were drawn from the BVH, so E_q[(c / q)^2] = E_bvh[c^2 / (q p)])
        q = _learned_probabilities(out, cell, points, normals, light)
        m_bvh, m_learned = _second_moments(cell, value, p_bvh, q, cells)
        worse = ~(m_learned < margin * m_bvh)
        nxt[leaves[worse[nxt[leaves, 0].clip(0)] & (nxt[leaves, 0] >= 0)], 0] = -1
        out = out._replace(cell_next=nxt)
    if not np.any(nxt[leaves, 0] >= 0):
        return sel  # no cell learned anything worth its cost: no tree to walk at every pick
    return out._replace(cell_axis=_pruned(axis, nxt))


def _pruned(axis: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """The tree's split axes with every subtree whose cells all learned nothing made one such leaf (a pick there
    stops its walk sooner); ``nxt`` is changed to match.  Children follow their parent in the arrays."""
    axis = axis.copy()
    for node in range(axis.shape[0] - 1, -1, -1):
        if axis[node] >= 0:
            a, b = nxt[node]
            if axis[a] < 0 and axis[b] < 0 and nxt[a, 0] < 0 and nxt[b, 0] < 0:
                axis[node] = -1
                nxt[node] = (-1, 0)
    return axis


def _learned_probabilities(sel, cell, points, normals, light):
    """Each record's light's probability under the learned selector (a bounded pick) in the record's cell."""
    q = np.zeros(points.shape[0])
    in_threads(_learned_probabilities_range, points.shape[0], sel, cell, points, normals, light, q)
    return q


@jit
def _learned_probabilities_range(sel, cell, points, normals, light, q, lo, hi):
    """Records lo .. hi - 1 of :func:`_learned_probabilities` (serial, run in threads: decisions.md 129)."""
    for i in range(lo, hi):
        if cell[i] >= 0:
            q[i] = _path_pmf(
                sel, cell[i], 1.0, np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2]),
                np.float64(normals[i, 0]), np.float64(normals[i, 1]), np.float64(normals[i, 2]), light[i],
            )  # fmt: skip


@jit_alloc
def _second_moments(cell, value, p_bvh, q, cells):
    """Per cell, the mean of (c / p)^2 and of c^2 / (q p) over its records (c the record's value, p its light's
    probability under the BVH, q under the learned selector): the second moments of the two selections' estimates,
    both from samples of the BVH."""
    m_bvh = np.zeros(cells)
    m_learned = np.zeros(cells)
    for i in range(cell.shape[0]):
        c = np.float64(value[i])
        if c > 0.0 and p_bvh[i] > 0.0:
            m_bvh[cell[i]] += c * c / (p_bvh[i] * p_bvh[i])
            m_learned[cell[i]] += c * c / (q[i] * p_bvh[i]) if q[i] > 0.0 else np.inf
    return m_bvh, m_learned


def _shrunk(sel: LightSelector, sums, importance, counts, tau: float) -> np.ndarray:
    """Each cell's ratios, each child's pulled toward its parent's by ``tau`` samples' worth (the root's children
    toward the cell's ratio over all of them)."""
    cells = sums.shape[0]
    ratio = np.zeros_like(sums)
    child = sel.wide_child
    parent_entry = {}  # a learned node's own entry in its parent's children
    for node in np.flatnonzero(sel.learn_offset >= 0):  # parents before children
        first = sel.learn_offset[node]
        columns = slice(first, first + WIDTH)
        if node == 0:
            total = importance[:, columns].sum(axis=1)
            parent = np.divide(sums[:, columns].sum(axis=1), total, out=np.zeros(cells), where=total > 0.0)
        else:
            parent = ratio[:, parent_entry[node]]
        n, seen = counts[:, columns], importance[:, columns]
        own = np.divide(sums[:, columns], seen, out=np.zeros((cells, WIDTH)), where=seen > 0.0)
        own = np.where(seen > 0.0, own, parent[:, None])
        ratio[:, columns] = (n * own + tau * parent[:, None]) / (n + tau)
        for c in range(WIDTH):
            k = child[node, c]
            if k >= 0 and sel.learn_offset[k] >= 0:
                parent_entry[k] = first + c
    return ratio


def _kd_tree(points: np.ndarray, leaf: int):
    """A k-d tree over ``points`` (leaves of at most ``leaf`` points): (axis, split, next) as
    ``LightSelector.cell_*``, each leaf's cell numbered in the order leaves are made."""
    n = points.shape[0]
    most = 2 * (n // max(1, leaf) + 1) * 2 + 1  # nodes: fewer than 2 n / (leaf / 2) + 1
    axis, split, nxt, count = _kd_build(points, max(1, leaf), most)
    return axis[:count].copy(), split[:count].copy(), nxt[:count].copy()


@jit
def _kth_smallest(values, k):
    """The k-th smallest of ``values`` (0-based), the array reordered in place: Hoare's selection with the middle
    element as pivot.  The value ``np.partition(values, k)[k]`` gives, without its implementation, which took 1.3 s
    of a first learned render's compile (decisions.md 130)."""
    lo, hi = 0, values.shape[0] - 1
    while lo < hi:
        pivot = values[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while values[i] < pivot:
                i += 1
            while values[j] > pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return values[k]
    return values[k]


@jit_alloc
def _kd_build(points, leaf, most):
    """:func:`_kd_tree`'s tree, splitting a node's points at the median of its widest axis; where more than half
    share the median's coordinate (a floor at y = 0 and the walls meeting it), at the next coordinate above it, or
    along the next axis; a node no axis splits in two non-empty halves is a leaf."""
    n = points.shape[0]
    order = np.arange(n)
    axis = np.full(most, -1, np.int64)
    split = np.zeros(most)
    nxt = np.zeros((most, 2), np.int64)
    stack_node = np.zeros(most, np.int64)
    stack_lo = np.zeros(most, np.int64)
    stack_hi = np.zeros(most, np.int64)
    scratch = np.empty(n, np.float64)
    top = 1
    stack_node[0], stack_lo[0], stack_hi[0] = 0, 0, n
    count = 1
    cells = 0
    while top > 0:
        top -= 1
        node, lo, hi = stack_node[top], stack_lo[top], stack_hi[top]
        size = hi - lo
        chosen, value = -1, 0.0
        if size > leaf and count + 2 <= most:
            low = np.full(3, np.inf)
            high = np.full(3, -np.inf)
            for i in range(lo, hi):
                for a in range(3):
                    x = np.float64(points[order[i], a])
                    low[a] = min(low[a], x)
                    high[a] = max(high[a], x)
            extent = high - low
            for _ in range(3):  # the axes, widest first
                a = int(np.argmax(extent))
                if not extent[a] > 0.0:
                    break
                extent[a] = -1.0
                for i in range(lo, hi):
                    scratch[i - lo] = points[order[i], a]
                values = scratch[:size]
                median = _kth_smallest(values, size // 2)
                below = 0
                above_min = np.inf
                for i in range(size):
                    if values[i] < median:
                        below += 1
                    elif values[i] > median:
                        above_min = min(above_min, values[i])
                if below == 0:
                    if above_min == np.inf:
                        continue
                    median = above_min
                    below = 0
                    for i in range(size):
                        if values[i] < median:
                            below += 1
                if 0 < below < size:
                    chosen, value = a, median
                    break
        if chosen < 0:
            nxt[node, 0] = cells
            cells += 1
            continue
        i, j = lo, hi - 1  # the points below the split first
        while i <= j:
            if points[order[i], chosen] < value:
                i += 1
            else:
                order[i], order[j] = order[j], order[i]
                j -= 1
        first = count
        count += 2
        axis[node], split[node] = chosen, value
        nxt[node, 0], nxt[node, 1] = first, first + 1
        stack_node[top], stack_lo[top], stack_hi[top] = first + 1, i, hi
        stack_node[top + 1], stack_lo[top + 1], stack_hi[top + 1] = first, lo, i
        top += 2
    return axis, split, nxt, count


def _record_terms(sel, axis, split, nxt, points, normals, light, value):
    """Each record's cell, and at each level above the cut the entry of the child its light's path takes, v there
    and the child's importance (entry -1: no level), and the light's probability under the BVH."""
    n = points.shape[0]
    levels = max(1, sel.cut_levels)
    cell = np.empty(n, np.int64)
    entry = np.full((n, levels), -1, np.int64)
    v_out = np.zeros((n, levels))
    weight_out = np.zeros((n, levels))
    p_out = np.zeros(n)
    in_threads(
        _record_terms_range, n, sel, axis, split, nxt, points, normals, light, value, cell, entry, v_out,
        weight_out, p_out,
    )  # fmt: skip
    return cell, entry, v_out, weight_out, p_out


@jit
def _record_terms_range(sel, axis, split, nxt, points, normals, light, value, cell, entry, v_out, weight_out, p_out,
                        lo, hi):  # fmt: skip
    """Records lo .. hi - 1 of :func:`_record_terms` (serial, run in threads: as a ``prange`` loop it compiled for
    2.8 s, decisions.md 129)."""
    for i in range(lo, hi):
        px, py, pz = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        nx, ny, nz = np.float64(normals[i, 0]), np.float64(normals[i, 1]), np.float64(normals[i, 2])
        cell[i] = leaf_of(axis, split, nxt, px, py, pz)
        trail = sel.light_trail[light[i]]
        node = 0
        depth = 0
        below = 1.0  # the probability of the light below the child taken at each level above the cut
        while True:  # the light's path: each level's share and the importance of the child taken
            slot = trail & (WIDTH - 1)
            trail >>= TRAIL_BITS
            w, total = _child_weights(sel.wide_bounds, node, px, py, pz, nx, ny, nz)
            if depth < sel.cut_levels:
                entry[i, depth] = sel.learn_offset[node] + slot
                weight_out[i, depth] = w[slot]
                v_out[i, depth] = w[slot] / total  # the share, until v takes its place below
            else:
                below *= w[slot] / total
            depth += 1
            child = sel.wide_child[node, slot]
            if child < 0:
                break
            node = child
        v = np.float64(value[i])
        for d in range(min(depth, sel.cut_levels) - 1, -1, -1):
            share = v_out[i, d]
            v_out[i, d] = v / below if v > 0.0 and below > 0.0 else 0.0
            below *= share
        p_out[i] = below  # the whole path's: the light's probability under the BVH


@jit_alloc
def _add_terms(cell, entry, v, weight, cells, entries):
    squares = np.zeros((cells, entries))
    importance = np.zeros((cells, entries))
    counts = np.zeros((cells, entries))
    for i in range(cell.shape[0]):
        for d in range(entry.shape[1]):
            e = entry[i, d]
            if e >= 0:
                squares[cell[i], e] += v[i, d] * v[i, d]
                importance[cell[i], e] += weight[i, d]
                counts[cell[i], e] += 1.0
    return squares, importance, counts
