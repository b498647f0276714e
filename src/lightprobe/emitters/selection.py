"""Choosing which light to sample: uniform, in proportion to power, with a light BVH, or with one that learns.

The lecture's many-light estimator picks light l with probability p_l and divides by it (1/(KN) sum f / (p_l p)),
so every selector offers ``select(p, n, u) -> (light, pmf, u')`` and ``pmf(p, n, light)`` for MIS (pbrt-v4's
``LightSampler::Sample / PMF``); u' is what is left of u after it chose the light, uniform on [0, 1) again, which the
renderer gives the light as the first number of its sample (decisions.md 74).  Lights are numbered as in the scene's
light table (:mod:`lightprobe.emitters.kinds`): the bounded lights first, then the infinite ones (directional lights,
then the environment map, the last row).

``uniform``
    p_l = 1 / L.
``power``
    p_l proportional to emitted power: pi A L (x 2 for two-sided lights) for an area light, pi R^2 times the
    integral of the map's luminance over the sphere for the environment (R the radius of the scene's bounding
    sphere; pbrt-v4's ``ImageInfiniteLight::Phi``).  A CDF search: O(log L) per pick.
``bvh``
    a light BVH (Conty Estevez & Kulla 2018, pbrt-v4's ``BVHLightSampler``): every node bounds its lights'
    positions (a box), power, and emission directions (a cone of normals plus the spread of emission about them);
    a pick descends from the root choosing each child in proportion to its importance for the shading point,
    phi cos(theta') / d^2 times the bound on the cosine at the receiver (pbrt-v4's ``LightBounds::Importance``),
    pi x the irradiance of a flat light of power phi facing the receiver.  So a sphere's phi is a quarter of its
    power (it faces every receiver with a disc, a quarter of its area) and a point or spot light's is pi I
    (decisions.md 75); pbrt-v4 takes their whole power and over-picks them 4x beside flat lights.
    O(depth) per pick and per pmf.  Nodes split where pbrt-v4's surface area orientation heuristic puts the cost
    lowest (12 buckets of centroids per axis; power x the measure of the normal cone x surface area per side), so
    lights that face apart do not share a node; where no bucket split separates the lights, and below depth 32,
    at the median centroid along the axis of largest extent (decisions.md 81).  The binary tree is then collapsed
    to eight children a node (:func:`_collapse`), whose importances the descent computes at once in vector lanes
    (``light_tree_lanes.py``): a third of the levels, each child weighed among seven siblings rather than one
    (decisions.md 90).
``learned``
    the BVH, weighed where the render's pilot found that shadows hide what the BVH expects: per cell of shading
    points, each child of the tree's top levels by a learned ratio of what its lights gave to its importance, a
    fifth of each level's choice left to the BVH's shares (``emitters/selection_learning.py`` learns the ratios,
    ``integrators/light_learning.py`` keeps the pilot's samples; decision 114).  Until a render has learned, and in
    cells that learned nothing, the same picks as ``bvh``; :func:`_descend` and :func:`_path_pmf` are both.

The infinite lights (``power``, ``bvh`` and ``learned``) are kept apart from the bounded ones, as pbrt-v4's
``BVHLightSampler`` keeps them, and chosen *per shading point*: together with probability I_inf / (I_inf + I_area),
each in proportion to its own I, where I_area is the importance of the root of the bounded lights' bounds for the
receiver (the BVH's own estimate of pi x their irradiance, pbrt-v4's ``LightBounds::Importance``) and an infinite
light's I = pi max(a + b . n, floor) is pi x its irradiance on the receiver: for the environment E_env(n) = a + b .
n to first order (its radiance's constant and linear terms: a = pi c0, b = 2 pi / 3 c1), floored at a / 4; for a
directional light E n . w_l, floored at E / 4 (emitters/directional.py). A global share by power (pi R^2 of the
scene's bounding sphere x the map's integral, pbrt-v4's ``ImageInfiniteLight::Phi``) gave a dim sky 89 % of the
picks in a scene with a 16 m ground, where uniform selection was more efficient (issue 32; decisions.md 71). The
bounded lights' ``power`` CDF and the BVH are then over the bounded lights alone. ``uniform`` keeps the infinite
lights among its L equally likely lights.

A receiver whose material samples the MIS-compensated environment (Karlik et al. 2019: the density of max(L - mean,
0), on Lambertian materials by default) weighs the environment by that luminance's irradiance instead
(``env_irradiance_compensated``): the part of the map's light that its BSDF samples find poorly.  A constant sky
then gets no light samples there; its BSDF samples find it alone, with no variance from the sky (decisions.md 98).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._numba import jit, jit_alloc, jit_inline, jit_parallel, prange
from .._worksharing import in_threads, read_only_rows
from ..color import luminance
from ..errors import ParameterError
from ..geometry.shape_bvh import push_halves, sort_along_widest_axis
from ..geometry.wide_tree import PATH_BITS, collapse
from .area import area_power
from .kinds import (
    LIGHT_ENVIRONMENT,
    LIGHT_POINT,
    LIGHT_RECT,
    LIGHT_SPHERE,
    LIGHT_SPOT,
    LIGHT_TRIANGLE,
    ROW_WIDTH,
    LightArrays,
    concatenate,
    flag_rows,
)
from .light_tree_lanes import (
    B_AXIS,
    B_CENTER,
    B_COS_E,
    B_COS_O,
    B_PHI,
    B_RADIUS,
    B_SIN_O,
    B_TWO_SIDED,
    BOUNDS_WIDTH,
    WIDTH,
    child_importances,
)
from .punctual import punctual_power

__all__ = [
    "SELECTORS",
    "LightSampler",
    "LightSelector",
    "build_selector",
    "infinite_probability",
    "no_receiver_terms",
    "power_of_lights",
    "receiver_terms",
    "select_light",
    "select_light_at",
    "selector_pmf",
]

SELECTORS = {"uniform": 0, "power": 1, "bvh": 2, "learned": 2}  # learned: a BVH, and what the render learns
UNIFORM, POWER, BVH = 0, 1, 2
MAX_DEPTH = 62  # the binary tree's depth: its eight-wide collapse's trails are int64 (TRAIL_BITS per level)
TRAIL_BITS = PATH_BITS  # a light's trail holds the child (0 .. WIDTH - 1) taken at each level of the eight-wide tree


class LightSelector(NamedTuple):
    """Arrays the kernels read.  Node arrays are empty unless ``mode == BVH``."""

    mode: int
    n_lights: int  # rows of the light table
    n_bounded: int  # its bounded lights, rows 0 .. n_bounded - 1; the infinite ones follow
    env_index: int  # the environment's row; -1: no environment
    # each infinite light's irradiance on a receiver with normal n, max(a + b . n, floor); row 0 for every
    # receiver, row 1 for a receiver whose material takes the MIS-compensated environment (the environment's terms
    # those of its compensated luminance: see infinite_probability)
    inf_a: np.ndarray  # (2, infinite lights)
    inf_b: np.ndarray  # (2, infinite lights, 3)
    inf_floor: np.ndarray  # (2, infinite lights)
    cdf: np.ndarray  # (bounded lights + 1,) power CDF over the bounded lights (POWER), empty otherwise
    # (1, 12) the bounds of every bounded light together (the environment's share: infinite_probability), columns
    # B_* (light_tree_lanes.py; a sphere's power a quarter of it: _light_bounds); (0, 12) without bounded lights
    # or in UNIFORM mode
    node_bounds: np.ndarray
    # the light tree (BVH), eight children a node (light_tree_lanes.py), node 0 the root; empty unless BVH:
    wide_bounds: np.ndarray  # (M, 12 * 8) each node's children's bounds: column f * 8 + c is field f of child c
    wide_child: np.ndarray  # (M, 8) child c: a node (>= 0), a light l (-2 - l), or none (-1)
    light_trail: np.ndarray  # (n_bounded,) each light's path from the root: bits 3d .. 3d + 2 the child at depth d
    # learned selection (``learned``; emitters/selection_learning.py): empty arrays and ``cut_levels`` 0 until the
    # render has learned.  Above the cut (``cut_levels`` levels of the tree) a learned cell weighs each child's
    # importance by a learned ratio; a cell is a leaf of a k-d tree over the shading points
    cut_levels: int
    learn_offset: np.ndarray  # (M,) int64 a node above the cut: its children's first entry in a cell's row; else -1
    cell_axis: np.ndarray  # (tree nodes,) int64 the k-d tree's split axis, -1 at a leaf
    cell_split: np.ndarray  # (tree nodes,) float64 below it: child 0, else child 1
    cell_next: np.ndarray  # (tree nodes, 2) int64 the children; at a leaf (its cell, 0), cell -1: none learned
    cell_ratio: np.ndarray  # (cells, entries) float64 each child's learned ratio of contribution to importance
    defensive: float  # alpha: the share of the BVH's own distribution in a learned cell's mixture


# --- light bounds (pbrt-v4 LightBounds, DirectionCone) ----------------------------------------------------------------
def _light_bounds(lights: LightArrays):
    """Per area light: box (lo, hi), power, normal axis w, cos_o, cos_e, two_sided."""
    n = lights.kind.shape[0]
    lo = np.empty((n, 3))
    hi = np.empty((n, 3))
    w = np.zeros((n, 3))
    cos_o = np.ones(n)
    cos_e = np.zeros(n)  # emission spreads over the hemisphere about the normal: theta_e = pi/2
    g = lights.geom
    for kind, sel in ((LIGHT_RECT, lights.kind == LIGHT_RECT), (LIGHT_TRIANGLE, lights.kind == LIGHT_TRIANGLE)):
        if not sel.any():
            continue
        if kind == LIGHT_RECT:
            o, a, b = g[sel, 0:3], g[sel, 3:6], g[sel, 6:9]
            corners = np.stack([o, o + a, o + b, o + a + b])
        else:
            corners = np.stack([g[sel, 0:3], g[sel, 3:6], g[sel, 6:9]])
        lo[sel], hi[sel] = corners.min(axis=0), corners.max(axis=0)
        w[sel] = g[sel, 9:12]
    sph = lights.kind == LIGHT_SPHERE
    if sph.any():
        c, r = g[sph, 0:3], g[sph, 3:4]
        lo[sph], hi[sph] = c - r, c + r
        w[sph] = (0.0, 0.0, 1.0)
        cos_o[sph] = -1.0  # normals point everywhere
    # delta lights (pbrt-v4's PointLight/SpotLight::Bounds): a point; a spot's cone of full intensity about its axis
    # and the falloff beyond it as the emission spread
    point, spot = lights.kind == LIGHT_POINT, lights.kind == LIGHT_SPOT
    lo[point | spot] = hi[point | spot] = g[point | spot, 0:3]
    w[point] = (0.0, 0.0, 1.0)
    cos_o[point] = -1.0
    w[spot], cos_o[spot] = g[spot, 3:6], g[spot, 7]
    cos_e[spot] = np.cos(np.maximum(np.arccos(np.clip(g[spot, 6], -1, 1)) - np.arccos(np.clip(g[spot, 7], -1, 1)), 0.0))
    phi = power_of_lights(lights)
    # The importance phi cos(theta') / d^2 is pi times the irradiance of a flat light of power phi facing the
    # receiver.  A sphere faces every receiver with its disc, pi r^2, a quarter of its area 4 pi r^2: with its whole
    # power (pbrt-v4's bound, a cone of all normals) it took 4x its share (on the area-light reference scene a
    # sphere got 0.83 of the picks on ground it lit less than the ring beside it; decisions.md 75).
    phi[sph] *= 0.25
    # likewise a point or spot light of intensity I lights a receiver facing it with I / d^2: phi = pi I
    phi[point | spot] = math.pi * luminance(lights.radiance[point | spot])
    return lo, hi, phi, w, cos_o, cos_e, lights.two_sided.astype(np.int64)


def power_of_lights(lights: LightArrays) -> np.ndarray:
    """Emitted power (of the luminance) of each bounded light: pi A L for an area light, doubled for two-sided ones;
    4 pi I for a point light, 2 pi I (1 - (cos_start + cos_total) / 2) for a spot (pbrt-v4's ``Phi``); 0 for the
    infinite lights (chosen by their irradiance, not their power)."""
    power = area_power(lights)
    punctual = flag_rows(lights.kind, "positional")
    power[punctual] = punctual_power(
        lights.kind[punctual] == LIGHT_SPOT, lights.geom[punctual], lights.radiance[punctual]
    )
    power[flag_rows(lights.kind, "infinite")] = 0.0
    return power


@jit
def _angle_between(ax, ay, az, bx, by, bz):
    """Angle between unit vectors a and b, accurate near 0 and pi (pbrt-v4's AngleBetween)."""
    if ax * bx + ay * by + az * bz < 0:
        return math.pi - 2 * math.asin(min(1.0, math.sqrt((ax + bx) ** 2 + (ay + by) ** 2 + (az + bz) ** 2) / 2))
    return 2 * math.asin(min(1.0, math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2) / 2))


@jit
def _union(wax, way, waz, cos_a, wbx, wby, wbz, cos_b):
    """The smallest cone holding cones (wa, cos_a) and (wb, cos_b) (pbrt-v4 DirectionCone Union): (axis, cos)."""
    theta_a, theta_b = math.acos(max(-1.0, min(1.0, cos_a))), math.acos(max(-1.0, min(1.0, cos_b)))
    theta_d = _angle_between(wax, way, waz, wbx, wby, wbz)
    if min(theta_d + theta_b, math.pi) <= theta_a:
        return wax, way, waz, cos_a
    if min(theta_d + theta_a, math.pi) <= theta_b:
        return wbx, wby, wbz, cos_b
    theta_o = (theta_a + theta_d + theta_b) / 2
    if theta_o >= math.pi:
        return 0.0, 0.0, 1.0, -1.0
    # the axis: wa rotated toward wb by theta_o - theta_a about wa x wb (Rodrigues)
    rx, ry, rz = way * wbz - waz * wby, waz * wbx - wax * wbz, wax * wby - way * wbx
    length = math.sqrt(rx * rx + ry * ry + rz * rz)
    if length == 0.0:
        return 0.0, 0.0, 1.0, -1.0
    rx, ry, rz = rx / length, ry / length, rz / length
    angle = theta_o - theta_a
    c, s = math.cos(angle), math.sin(angle)
    along = rx * wax + ry * way + rz * waz
    x = wax * c + (ry * waz - rz * way) * s + rx * along * (1 - c)
    y = way * c + (rz * wax - rx * waz) * s + ry * along * (1 - c)
    z = waz * c + (rx * way - ry * wax) * s + rz * along * (1 - c)
    length = math.sqrt(x * x + y * y + z * z)
    return x / length, y / length, z / length, math.cos(theta_o)


def _build_bvh(lights: LightArrays):
    """The binary BVH's node arrays (a dict) and its node count, built in compiled code (:func:`_build_tree`;
    100,000 lights in a fraction of a second, where the NumPy builder took 4.7 s)."""
    lo, hi, phi, w, cos_o, cos_e, two = _light_bounds(lights)
    emitting = np.nonzero(phi > 0)[0]  # a light with no power is never picked (its pmf is 0)
    m = max(1, 2 * emitting.size - 1)
    nodes = _root_nodes(m)
    if emitting.size == 0:
        return nodes, 0
    if math.ceil(math.log2(emitting.size)) > MAX_DEPTH:
        raise ParameterError(f"light BVH deeper than {MAX_DEPTH} levels ({lo.shape[0]} lights)")
    _build_tree(
        lo,
        hi,
        phi,
        w,
        cos_o,
        cos_e,
        two,
        emitting,
        *(nodes[k] for k in ("lo", "hi", "phi", "w", "cos_o", "cos_e", "two", "second", "light")),
    )
    return nodes, m


SAOH_BUCKETS = 12  # pbrt-v4's
SAOH_DEPTH = MAX_DEPTH - 30  # below it, median splits: 2^30 lights still fit the trail


@jit
def _orientation_measure(cos_o, cos_e):
    """pbrt-v4's M_omega: the solid-angle measure of a cone of normals (theta_o) widened by the emission spread
    (theta_e), the orientation factor of the split cost."""
    theta_o = math.acos(max(-1.0, min(1.0, cos_o)))
    theta_e = math.acos(max(-1.0, min(1.0, cos_e)))
    theta_w = min(theta_o + theta_e, math.pi)
    sin_o = math.sqrt(max(0.0, 1.0 - cos_o * cos_o))
    return 2 * math.pi * (1 - cos_o) + math.pi / 2 * (
        2 * theta_w * sin_o - math.cos(theta_o - 2 * theta_w) - 2 * theta_o * sin_o + cos_o
    )


@jit
def _bounds_cost(dx, dy, dz, phi, cos_o, cos_e, kr):
    """pbrt-v4's LightBVHAggregate::EvaluateCost for a box of extents (dx, dy, dz): power x orientation measure x
    surface area x the box's aspect regulariser kr."""
    area = 2 * (dx * dy + dy * dz + dz * dx)
    return phi * _orientation_measure(cos_o, cos_e) * kr * area


@jit
def _cone_union(wx, wy, wz, cos_a, vx, vy, vz, cos_b):
    """:func:`_union`, without its trigonometry where the answer is plain: an empty cone (cos > 1) takes the other,
    equal cones stay, a cone of every direction stays so (the common cases among thousands of like lights)."""
    if cos_a > 1.0:
        return vx, vy, vz, cos_b
    if cos_a <= -1.0 or (wx == vx and wy == vy and wz == vz and cos_b >= cos_a):
        return wx, wy, wz, cos_a
    return _union(wx, wy, wz, cos_a, vx, vy, vz, cos_b)


@jit
def _side_costs(k, side_scratch, kr, first, stop, step, plus, out):
    """out[x] = the cost (:func:`_bounds_cost`) of buckets ``first`` .. x together, plus plus[x + 1], for x from
    ``first`` toward ``stop`` (exclusive) by ``step``; inf while they hold no light.  Swept down from the last bucket
    with ``plus`` 0 it gives the right sides' costs; swept up with ``plus`` those, each split's whole cost (split x
    puts buckets 0 .. x on the left).  ``k`` and ``side_scratch`` as :func:`_saoh_split` fills them."""
    lo0 = lo1 = lo2 = np.inf
    hi0 = hi1 = hi2 = -np.inf
    w0, w1, w2, cos_o, phi, cos_e, count = 0.0, 0.0, 1.0, 2.0, 0.0, 1.0, 0.0  # cos_o 2: no cone yet
    for x in range(first, stop, step):
        if side_scratch[x, 2] > 0:
            lo0, lo1, lo2 = min(lo0, k[x, 0]), min(lo1, k[x, 1]), min(lo2, k[x, 2])
            hi0, hi1, hi2 = max(hi0, k[x, 3]), max(hi1, k[x, 4]), max(hi2, k[x, 5])
            w0, w1, w2, cos_o = _cone_union(w0, w1, w2, cos_o, k[x, 6], k[x, 7], k[x, 8], k[x, 9])
            phi += side_scratch[x, 0]
            cos_e = min(cos_e, side_scratch[x, 1])
            count += side_scratch[x, 2]
        if count > 0:
            out[x] = _bounds_cost(hi0 - lo0, hi1 - lo1, hi2 - lo2, phi, cos_o, cos_e, kr) + plus[x + 1]
        else:
            out[x] = np.inf


@jit_alloc
def _saoh_split(order, start, end, centroid, lo, hi, phi, w, cos_o, cos_e, scratch, side_scratch):
    """Partition ``order[start:end]`` by the cheapest of pbrt-v4's bucket splits (12 buckets of centroid along each
    axis; cost = sum over both sides of power x M_omega x surface area x the aspect regulariser) and return the
    left side's count; 0 where no bucket split separates the lights or every split costs 0. A median split pairs
    lights that face apart (on the area-light scene an upward rectangle with a downward triangle: the pair's cone
    takes every direction, and the triangle inherited the rectangle's power, a third of all picks at ground
    points it barely lights). ``scratch`` (12, 10) holds each bucket's box (lo, hi) and normal cone (axis, cos);
    ``side_scratch`` (12, 3) its power, emission cosine and count."""
    n = end - start
    c_lo0 = c_lo1 = c_lo2 = np.inf
    c_hi0 = c_hi1 = c_hi2 = -np.inf
    b_lo0 = b_lo1 = b_lo2 = np.inf
    b_hi0 = b_hi1 = b_hi2 = -np.inf
    for j in range(start, end):
        light = order[j]
        c_lo0, c_hi0 = min(c_lo0, centroid[light, 0]), max(c_hi0, centroid[light, 0])
        c_lo1, c_hi1 = min(c_lo1, centroid[light, 1]), max(c_hi1, centroid[light, 1])
        c_lo2, c_hi2 = min(c_lo2, centroid[light, 2]), max(c_hi2, centroid[light, 2])
        b_lo0, b_hi0 = min(b_lo0, lo[light, 0]), max(b_hi0, hi[light, 0])
        b_lo1, b_hi1 = min(b_lo1, lo[light, 1]), max(b_hi1, hi[light, 1])
        b_lo2, b_hi2 = min(b_lo2, lo[light, 2]), max(b_hi2, hi[light, 2])
    c_lo = (c_lo0, c_lo1, c_lo2)
    c_ext = (c_hi0 - c_lo0, c_hi1 - c_lo1, c_hi2 - c_lo2)
    b_ext = (b_hi0 - b_lo0, b_hi1 - b_lo1, b_hi2 - b_lo2)
    widest = max(b_ext[0], b_ext[1], b_ext[2])
    nb = SAOH_BUCKETS
    k = scratch
    none = np.zeros(nb + 1)
    right_cost = np.full(nb + 1, np.inf)
    split_cost = np.empty(nb)
    best_cost, best_axis, best_split = np.inf, -1, -1
    for a in range(3):
        extent = c_ext[a]
        if not extent > 0.0:
            continue
        kr = widest / max(b_ext[a], 1e-300)
        for x in range(nb):
            k[x, 0] = k[x, 1] = k[x, 2] = np.inf
            k[x, 3] = k[x, 4] = k[x, 5] = -np.inf
            k[x, 6], k[x, 7], k[x, 8], k[x, 9] = 0.0, 0.0, 1.0, 2.0  # cos_o 2: no cone yet
            side_scratch[x, 0] = 0.0  # power
            side_scratch[x, 1] = 1.0  # cos_e
            side_scratch[x, 2] = 0.0  # count
        for j in range(start, end):
            light = order[j]
            x = min(nb - 1, int(nb * (centroid[light, a] - c_lo[a]) / extent))
            for t in range(3):
                k[x, t] = min(k[x, t], lo[light, t])
                k[x, 3 + t] = max(k[x, 3 + t], hi[light, t])
            k[x, 6], k[x, 7], k[x, 8], k[x, 9] = _cone_union(
                k[x, 6], k[x, 7], k[x, 8], k[x, 9], w[light, 0], w[light, 1], w[light, 2], cos_o[light]
            )
            side_scratch[x, 0] += phi[light]
            side_scratch[x, 1] = min(side_scratch[x, 1], cos_e[light])
            side_scratch[x, 2] += 1.0
        # (int64 bounds, not literals: one compiled _side_costs for both sweeps, not one per literal)
        _side_costs(k, side_scratch, kr, nb - 1, np.int64(0), np.int64(-1), none, right_cost)  # x .. 11: right sides
        _side_costs(k, side_scratch, kr, np.int64(0), nb - 1, np.int64(1), right_cost, split_cost)  # + 0 .. x: splits
        for split in range(nb - 1):
            cost = split_cost[split]
            if 0.0 < cost < best_cost:  # as pbrt-v4: boxes of no area (point lights) cost nothing, and say nothing
                best_cost, best_axis, best_split = cost, a, split
    if best_axis < 0:
        return 0
    # stable partition: the left buckets' lights first, each side in its former order
    a = best_axis
    extent = c_ext[a]
    right = np.empty(n, np.int64)
    n_left = n_right = 0
    for j in range(start, end):
        light = order[j]
        x = min(nb - 1, int(nb * (centroid[light, a] - c_lo[a]) / extent))
        if x <= best_split:
            order[start + n_left] = light  # never ahead of j: safe in place
            n_left += 1
        else:
            right[n_right] = light
            n_right += 1
    for j in range(n_right):
        order[start + n_left + j] = right[j]
    return n_left


@jit_alloc
def _build_tree(
    lo, hi, phi, w, cos_o, cos_e, two, emitting, n_lo, n_hi, n_phi, n_w, n_cos_o, n_cos_e, n_two, second, leaf
):
    """Splits by pbrt-v4's surface area orientation heuristic (:func:`_saoh_split`; median splits along the axis of
    largest centroid extent where it finds none), depth first: node i's first child is i + 1, its second
    i + 2 |first child's lights| (that subtree has 2 k - 1 nodes); then the normal cones bottom-up."""
    order = emitting.copy()
    centroid = 0.5 * (lo + hi)
    m = n_phi.shape[0]
    stack = np.empty((MAX_DEPTH + 2, 4), np.int64)  # node, start, end, depth
    scratch = np.empty((SAOH_BUCKETS, 10))
    side_scratch = np.empty((SAOH_BUCKETS, 3))
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, 0, order.shape[0], 0
    top = 1
    while top > 0:
        top -= 1
        node, start, end, depth = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        for a in range(3):
            n_lo[node, a] = np.inf
            n_hi[node, a] = -np.inf
        n_phi[node] = 0.0
        n_two[node] = 0
        n_cos_e[node] = np.inf
        for j in range(start, end):
            light = order[j]
            for a in range(3):
                n_lo[node, a] = min(n_lo[node, a], lo[light, a])
                n_hi[node, a] = max(n_hi[node, a], hi[light, a])
            n_phi[node] += phi[light]
            n_two[node] = max(n_two[node], two[light])
            n_cos_e[node] = min(n_cos_e[node], cos_e[light])
        if end - start == 1:
            light = order[start]
            leaf[node] = light
            for a in range(3):
                n_w[node, a] = w[light, a]
            n_cos_o[node] = cos_o[light]
            continue
        if depth < SAOH_DEPTH:
            half = _saoh_split(order, start, end, centroid, lo, hi, phi, w, cos_o, cos_e, scratch, side_scratch)
        else:  # deep below (a degenerate layout): median splits keep the bit trail within MAX_DEPTH
            half = 0
        if half <= 0 or half >= end - start:
            sort_along_widest_axis(centroid, order, start, end)
            half = (end - start) // 2
        second[node] = node + 2 * half
        top = push_halves(stack, top, node, start, end, half, depth)
    for node in range(m - 1, -1, -1):  # children have larger indices than their parent
        b = second[node]
        if b < 0:
            continue
        a = node + 1
        x, y, z, c = _union(n_w[a, 0], n_w[a, 1], n_w[a, 2], n_cos_o[a], n_w[b, 0], n_w[b, 1], n_w[b, 2], n_cos_o[b])
        n_w[node, 0], n_w[node, 1], n_w[node, 2], n_cos_o[node] = x, y, z, c


def _collapse(rows, second, leaf, n_bounded):
    """The eight-wide tree of the binary one (node i's children i + 1 and ``second[i]``, bounds ``rows``, a leaf's
    light ``leaf[i]``; geometry/wide_tree.py): (wide_bounds, wide_child, light_trail, deepest level).  A binary
    tree of MAX_DEPTH levels gives trails of at most 21 levels of TRAIL_BITS."""
    kids, child, _, path, deepest = collapse(second, np.arange(1, second.shape[0] + 1))
    leaves = child <= -2
    child[leaves] = -2 - leaf[-2 - child[leaves]]  # a binary leaf's number -> its light's
    trail = np.zeros(n_bounded, np.int64)
    is_leaf = second < 0
    trail[leaf[is_leaf]] = path[is_leaf]
    fields = rows[np.maximum(kids, 0)]  # (W, 8, 12): child c's bounds, field by field below
    fields[kids < 0] = 0.0
    fields[kids < 0, B_COS_E] = 2.0  # an empty child: importance 0 (and power 0)
    wide_bounds = np.ascontiguousarray(fields.transpose(0, 2, 1).reshape(-1, BOUNDS_WIDTH * WIDTH))
    return wide_bounds, child, trail, deepest


# --- kernels ---------------------------------------------------------------------------------------------------------
@jit
def _cos_sub_clamped(sin_a, cos_a, sin_b, cos_b):
    """cos(max(0, theta_a - theta_b))."""
    if cos_a > cos_b:
        return 1.0
    return cos_a * cos_b + sin_a * sin_b


@jit
def _sin_sub_clamped(sin_a, cos_a, sin_b, cos_b):
    if cos_a > cos_b:
        return 0.0
    return sin_a * cos_b - cos_a * sin_b


@jit_inline
def node_importance(bounds, i, px, py, pz, nx, ny, nz):
    """pbrt-v4 LightBounds::Importance of node i (row i of ``node_bounds``) for a receiver at p with normal n."""
    # the box's centre, its bounding sphere's radius and the cone's sine are the node's own (build_selector)
    b = bounds[i]
    radius = b[B_RADIUS]
    dx, dy, dz = px - b[B_CENTER], py - b[B_CENTER + 1], pz - b[B_CENTER + 2]
    d2 = dx * dx + dy * dy + dz * dz
    # The descent waits for each level's importances, so what counts is the longest chain of dependent square roots
    # and divisions: each cosine is a dot product with d and each sine sqrt(d2 - (a . d)^2), both scaled by 1 / |d|
    # at the end, so the four square roots run side by side instead of after the direction's (in the eight-wide
    # descent's float64 lanes, a level's importances 80 -> 76 ns; decisions.md 90).  At d = 0 (inv_dist 0) every
    # cosine and sine is 0: inside the bound, cos_p is 1 as before.
    dist = math.sqrt(d2)
    inv_dist = 1.0 / dist if dist > 0.0 else 0.0
    falloff = 1.0 / max(d2, radius)  # pbrt-v4: max(d2, Length(diagonal) / 2)
    along = b[B_AXIS] * dx + b[B_AXIS + 1] * dy + b[B_AXIS + 2] * dz
    if b[B_TWO_SIDED] == 1.0:
        along = abs(along)
    cos_w = along * inv_dist
    sin_w = math.sqrt(max(0.0, d2 - along * along)) * inv_dist
    # directions subtended by the box's bounding sphere: sin(theta_b) = radius / dist
    if dist <= radius:
        cos_b, sin_b = -1.0, 0.0
    else:
        sin_b = radius * inv_dist
        cos_b = math.sqrt(max(0.0, d2 - radius * radius)) * inv_dist
    cos_o = b[B_COS_O]
    sin_o = b[B_SIN_O]
    cos_x = _cos_sub_clamped(sin_w, cos_w, sin_o, cos_o)
    sin_x = _sin_sub_clamped(sin_w, cos_w, sin_o, cos_o)
    cos_p = _cos_sub_clamped(sin_x, cos_x, sin_b, cos_b)
    if cos_p <= b[B_COS_E]:
        return 0.0
    importance = b[B_PHI] * cos_p * falloff
    if nx != 0.0 or ny != 0.0 or nz != 0.0:
        facing = abs(nx * dx + ny * dy + nz * dz)
        cos_i = facing * inv_dist
        sin_i = math.sqrt(max(0.0, d2 - facing * facing)) * inv_dist
        importance *= _cos_sub_clamped(sin_i, cos_i, sin_b, cos_b)
    return max(importance, 0.0)


@jit_inline
def _sum8(w):
    """The sum of eight weights, pairwise (the same bits wherever a node's weights are summed)."""
    return ((w[0] + w[1]) + (w[2] + w[3])) + ((w[4] + w[5]) + (w[6] + w[7]))


@jit_inline
def _child_weights(wide_bounds, node, px, py, pz, nx, ny, nz):
    """(the eight children's importances, their sum) for the receiver, the eight at once (light_tree_lanes.py);
    where all are zero (the parent's looser bound let the descent reach a subtree that cannot light the receiver),
    their powers instead, so that the pmf over all lights sums to one (pbrt-v4 returns no light there; either way
    the sample contributes nothing and nothing is biased)."""
    w = child_importances(wide_bounds, node, px, py, pz, nx, ny, nz)
    total = _sum8(w)
    if total > 0.0:
        return w, total
    phi = B_PHI * WIDTH
    row = wide_bounds[node]
    w = (row[phi], row[phi + 1], row[phi + 2], row[phi + 3], row[phi + 4], row[phi + 5], row[phi + 6], row[phi + 7])
    return w, _sum8(w)


@jit_inline
def _no_bounds(sel):
    """No bounded light emits (or the selector keeps no bounds)."""
    return sel.node_bounds.shape[0] == 0 or sel.node_bounds[0, B_PHI] <= 0.0


@jit_inline
def _infinite_importance(sel, i, nx, ny, nz, compensated):
    """pi x infinite light i's irradiance on a receiver with normal n, floored (never 0 where the light exists,
    unless ``compensated`` and the light's compensated luminance is 0 everywhere: a constant map)."""
    c = 1 if compensated else 0
    e = sel.inf_a[c, i] + sel.inf_b[c, i, 0] * nx + sel.inf_b[c, i, 1] * ny + sel.inf_b[c, i, 2] * nz
    return math.pi * max(e, sel.inf_floor[c, i])


@jit_inline
def infinite_probability(sel, px, py, pz, nx, ny, nz, compensated):
    """(probability of choosing an infinite light for a receiver at p with normal n, the infinite lights' summed
    importance) for ``power`` and ``bvh`` (see the module docstring): I_inf / (I_inf + I_area); 0 without infinite
    lights or where their importance is 0 (the bounded lights' is then not weighed), 1 without bounded ones.
    ``compensated``: the receiver's material samples the MIS-compensated environment (Karlik et al. 2019), so the
    environment weighs what its compensated luminance max(L - mean, 0) gives, the part of its light that BSDF samples
    find poorly; a constant sky then gets no picks at all and its light comes from the BSDF samples, which find it
    with no variance from the sky (decisions.md 98)."""
    n_inf = sel.n_lights - sel.n_bounded
    if n_inf == 0:
        return 0.0, 0.0
    i_inf = 0.0
    for i in range(n_inf):
        i_inf += _infinite_importance(sel, i, nx, ny, nz, compensated)
    if i_inf <= 0.0:  # a constant map for a compensated receiver: never picked, whatever the bounded lights weigh
        return 0.0, 0.0
    if _no_bounds(sel):
        return 1.0, i_inf
    i_area = node_importance(sel.node_bounds, 0, px, py, pz, nx, ny, nz)
    if i_inf + i_area <= 0.0:
        return 0.5, i_inf
    return i_inf / (i_inf + i_area), i_inf


ONE_MINUS_EPSILON = 1.0 - 2.0**-53  # the largest double below 1


@jit_inline
def _rescaled(u, lo, width):
    """u's position inside the interval [lo, lo + width) it fell in, as a number in [0, 1): what is left of u after
    it chose that interval (pbrt-v4's BVHLightSampler, Mitsuba 3's ``sample_reuse``)."""
    return min(max((u - lo) / width, 0.0), ONE_MINUS_EPSILON)


@jit_inline
def receiver_terms(sel, px, py, pz, nx, ny, nz, compensated):
    """What every pick for one receiver shares, worked out once for the K picks of a camera sample (decisions.md
    120): (the probability of an infinite light, the infinite lights' summed importance, the learned cell, the
    importances of the tree root's eight children, their sum); the last three only for the BVH's descent."""
    p_inf, i_inf = 0.0, 0.0
    if sel.n_lights > sel.n_bounded and sel.mode != UNIFORM:
        p_inf, i_inf = infinite_probability(sel, px, py, pz, nx, ny, nz, compensated)
    cell, total = -1, 0.0
    w = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if sel.mode == BVH and not _no_bounds(sel):
        cell = cell_of(sel, px, py, pz)
        w, total = _child_weights(sel.wide_bounds, 0, px, py, pz, nx, ny, nz)
    return p_inf, i_inf, cell, w, total


@jit_inline
def no_receiver_terms():
    """:func:`receiver_terms`' types with no receiver's values: what a loop holds before its first receiver (a copy
    of receiver_terms inlined only to type that variable cost 1.8 s of compiling; decisions.md 130)."""
    return 0.0, 0.0, -1, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0.0


@jit_inline
def select_light(sel, px, py, pz, nx, ny, nz, u, compensated):
    """(light index, probability, u rescaled) for a receiver at p with normal n (``compensated``: its material
    samples the MIS-compensated environment, ``infinite_probability``); (-1, 0, u) when no light can be picked.
    The third value is u's position inside the sub-interval of [0, 1) that chose the light, a fresh uniform number:
    the renderer picks with the first number of the light sample's 2D pair and gives the pair back to the light
    with this number in its place, so each light's samples keep the pair's stratification (a separate pick number
    leaves each light a scattered subset of the pair's net)."""
    return select_light_at(sel, receiver_terms(sel, px, py, pz, nx, ny, nz, compensated), px, py, pz, nx, ny, nz, u,
                           compensated)  # fmt: skip


@jit_inline
def select_light_at(sel, terms, px, py, pz, nx, ny, nz, u, compensated):
    """:func:`select_light` with the receiver's shared ``terms`` (:func:`receiver_terms` of the same receiver and
    ``compensated``) already worked out: the same light, probability and number, bit for bit."""
    if sel.n_lights == 0:
        return -1, 0.0, u
    if sel.mode == UNIFORM:
        x = u * sel.n_lights
        light = min(int(x), sel.n_lights - 1)
        return light, 1.0 / sel.n_lights, _rescaled(x, float(light), 1.0)
    pmf = 1.0
    if sel.n_lights > sel.n_bounded:
        p_inf, i_inf = terms[0], terms[1]
        if u < p_inf:
            u = _rescaled(u, 0.0, p_inf)
            n_inf = sel.n_lights - sel.n_bounded
            if n_inf == 1:  # one infinite light (the environment, most often): it is the choice
                return sel.n_bounded, p_inf, u
            lo = 0.0
            for i in range(n_inf):  # a few lights: a linear search of their importances
                width = _infinite_importance(sel, i, nx, ny, nz, compensated) / i_inf if i_inf > 0.0 else 1.0 / n_inf
                if u < lo + width or i == n_inf - 1:
                    return sel.n_bounded + i, p_inf * width, _rescaled(u, lo, width)
                lo += width
        if p_inf >= 1.0:
            return -1, 0.0, u
        pmf = 1.0 - p_inf
        u = _rescaled(u, p_inf, pmf)
    if sel.mode == POWER:
        cdf = sel.cdf
        lo, hi = 0, cdf.shape[0] - 2
        while lo < hi:  # the first bin whose upper edge exceeds u
            mid = (lo + hi) // 2
            if cdf[mid + 1] <= u:
                lo = mid + 1
            else:
                hi = mid
        width = cdf[lo + 1] - cdf[lo]
        return lo, pmf * width, _rescaled(u, cdf[lo], width)
    # BVH: down the eight-wide tree, each child in proportion to its weight
    if _no_bounds(sel):
        return -1, 0.0, u
    return _descend(sel, terms[2], pmf, px, py, pz, nx, ny, nz, u, terms[3], terms[4])


# --- learned selection (emitters/selection_learning.py learns the ratios) --------------------------------------------
@jit_inline
def cell_of(sel, px, py, pz):
    """The learned cell of a receiver at p: the leaf of the k-d tree over the shading points it falls in; -1 where
    nothing was learned (or the selector has not learned)."""
    if sel.cell_axis.shape[0] == 0:
        return -1
    return leaf_of(sel.cell_axis, sel.cell_split, sel.cell_next, px, py, pz)


@jit_inline
def leaf_of(axis, split, nxt, px, py, pz):
    """What the leaf of a k-d tree (``LightSelector.cell_*``'s layout) that p falls in holds: below a node's split
    along its axis, child 0, else child 1."""
    node = 0
    while axis[node] >= 0:
        x = px if axis[node] == 0 else (py if axis[node] == 1 else pz)
        node = nxt[node, 0 if x < split[node] else 1]
    return nxt[node, 0]


@jit_inline
def _learned_scale(sel, cell, node, w):
    """(1 / sum of the children's importances x their learned ratios in ``cell``, the node's first entry in the
    cell's row); 0 where no child has a ratio above 0 (the node then keeps the BVH's shares)."""
    base = sel.learn_offset[node]
    t = 0.0
    for c in range(WIDTH):
        t += w[c] * sel.cell_ratio[cell, base + c]
    return (1.0 / t if t > 0.0 else 0.0), base


@jit_inline
def _share(sel, cell, base, w, c, scale, scale_r):
    """Child c's probability: the BVH's, w_c / sum w (``scale`` = 1 / sum w), or at a learned node (``scale_r`` >
    0) alpha x that + (1 - alpha) x its share of importance x learned ratio."""
    if scale_r == 0.0:
        return w[c] * scale  # the very expression _descend and _path_pmf both use, so both report the same bits
    alpha = sel.defensive
    return alpha * (w[c] * scale) + (1.0 - alpha) * (w[c] * sel.cell_ratio[cell, base + c] * scale_r)


@jit_inline
def _descend(sel, cell, pmf, px, py, pz, nx, ny, nz, u, root_w, root_total):
    """select_light's bounded pick (``pmf``: the probability of a bounded light so far): down the eight-wide tree,
    each child by :func:`_share` -- the BVH's share, or, above the cut in a learned ``cell`` (>= 0), the learned
    mixture; the root's children weigh ``root_w`` (summing to ``root_total``: :func:`receiver_terms`).
    :func:`_path_pmf` repeats the operations along a light's trail."""
    node = 0
    depth = 0
    w, total = root_w, root_total
    while True:
        if depth > 0:
            w, total = _child_weights(sel.wide_bounds, node, px, py, pz, nx, ny, nz)
        scale = 1.0 / total
        scale_r, base = 0.0, 0
        if cell >= 0 and depth < sel.cut_levels:
            scale_r, base = _learned_scale(sel, cell, node, w)
        chosen, start, width, lo = -1, 0.0, 0.0, 0.0
        for c in range(WIDTH):
            share = _share(sel, cell, base, w, c, scale, scale_r)
            if share > 0.0:
                chosen, start, width = c, lo, share  # the last child with a share, where rounding leaves u past all
                if u < lo + share:
                    break
            lo += share
        if chosen < 0:
            return -1, 0.0, u
        pmf *= width
        u = _rescaled(u, start, width)
        child = sel.wide_child[node, chosen]
        if child < 0:
            return -2 - child, pmf, u
        node = child
        depth += 1


@jit_inline
def _path_pmf(sel, cell, pmf, px, py, pz, nx, ny, nz, light):
    """The probability that :func:`_descend` picks bounded ``light`` (``pmf``: that of a bounded pick)."""
    trail = sel.light_trail[light]
    node = 0
    depth = 0
    while True:
        slot = trail & (WIDTH - 1)
        trail >>= TRAIL_BITS
        w, total = _child_weights(sel.wide_bounds, node, px, py, pz, nx, ny, nz)
        scale = 1.0 / total
        scale_r, base = 0.0, 0
        if cell >= 0 and depth < sel.cut_levels:
            scale_r, base = _learned_scale(sel, cell, node, w)
        pmf *= _share(sel, cell, base, w, slot, scale, scale_r)
        child = sel.wide_child[node, slot]
        if child == -1:
            return 0.0
        if child < 0:
            return pmf if -2 - child == light else 0.0  # a light without power (never picked) ends elsewhere
        node = child
        depth += 1


@jit
def selector_pmf(sel, px, py, pz, nx, ny, nz, light, compensated):
    """Probability that :func:`select_light` picks ``light`` for this receiver (``compensated`` as there).  Called,
    not inlined: the BSDF-ray stage needs it in two places, and each inlined copy of the descent was compiled again
    (decisions.md 130)."""
    if light < 0 or light >= sel.n_lights:
        return 0.0
    if sel.mode == UNIFORM:
        return 1.0 / sel.n_lights
    pmf = 1.0
    if sel.n_lights > sel.n_bounded:
        p_inf, i_inf = infinite_probability(sel, px, py, pz, nx, ny, nz, compensated)
        if light >= sel.n_bounded:
            n_inf = sel.n_lights - sel.n_bounded
            if n_inf == 1:
                return p_inf
            if i_inf <= 0.0:
                return p_inf / n_inf
            return p_inf * (_infinite_importance(sel, light - sel.n_bounded, nx, ny, nz, compensated) / i_inf)
        pmf = 1.0 - p_inf
    if sel.mode == POWER:
        return pmf * (sel.cdf[light + 1] - sel.cdf[light])
    if _no_bounds(sel):
        return 0.0
    return _path_pmf(sel, cell_of(sel, px, py, pz), pmf, px, py, pz, nx, ny, nz, light)


@jit
def _select_range(sel, points, normals, u, compensated, light, pmf, rest, lo, hi):
    """Receivers lo .. hi - 1: :func:`select_light`'s pick.  A serial range kernel that
    ``_worksharing.in_threads`` runs in threads: as a ``prange`` loop around the inlined descent it compiled in
    6.4-7.2 s, now 3.1 s (the same picks, as fast; decisions.md 130)."""
    for i in range(lo, hi):
        light[i], pmf[i], rest[i] = select_light(
            sel, points[i, 0], points[i, 1], points[i, 2], normals[i, 0], normals[i, 1], normals[i, 2], u[i],
            compensated,
        )  # fmt: skip


def _select_batch(sel, points, normals, u, compensated):
    n = u.shape[0]
    light, pmf, rest = np.empty(n, np.int64), np.empty(n), np.empty(n)
    in_threads(_select_range, n, sel, points, normals, u, compensated, light, pmf, rest)
    return light, pmf, rest


@jit
def _pmf_range(sel, points, normals, light, compensated, out, lo, hi):
    """Receivers lo .. hi - 1: :func:`selector_pmf` of each one's light (a range kernel, as :func:`_select_range`)."""
    for i in range(lo, hi):
        out[i] = selector_pmf(
            sel, points[i, 0], points[i, 1], points[i, 2], normals[i, 0], normals[i, 1], normals[i, 2], light[i],
            compensated,
        )  # fmt: skip


def _pmf_rows(sel, points, normals, light, compensated):
    out = np.empty(light.shape[0])
    in_threads(_pmf_range, light.shape[0], sel, points, normals, light, compensated, out)
    return out


@jit_parallel
def _pmf_all(sel, p, n, compensated):
    out = np.empty(sel.n_lights)
    for light in prange(sel.n_lights):
        # prange's index is unsigned: as int64, selector_pmf keeps the one signature the renders compile
        out[light] = selector_pmf(sel, p[0], p[1], p[2], n[0], n[1], n[2], np.int64(light), compensated)
    return out


# --- construction ----------------------------------------------------------------------------------------------------
def build_selector(
    mode: str, lights: LightArrays, *, env_irradiance=None, env_irradiance_compensated=None
) -> LightSelector:
    """A selector over the light table ``lights`` (bounded rows first, then the infinite ones: kinds.py).
    ``env_irradiance`` = (a, bx, by, bz), the environment's irradiance to first order, E(n) = a + b . n
    (:meth:`EnvironmentMap.irradiance_terms`), is required when the table has an environment row; given for a table
    without one, a row is added for it (the last).  ``env_irradiance_compensated``: the same of the map's
    compensated luminance (:meth:`EnvironmentMap.compensated_irradiance_terms`), what receivers whose material
    samples the compensated environment weigh it by (``infinite_probability``); ``env_irradiance`` if not given."""
    if mode not in SELECTORS:
        raise ParameterError(f"light sampler must be one of {list(SELECTORS)}, got {mode!r}")
    env = _irradiance_terms(env_irradiance, "env_irradiance")
    env_compensated = (
        env
        if env_irradiance_compensated is None
        else _irradiance_terms(env_irradiance_compensated, "env_irradiance_compensated")
    )
    kinds = lights.kind
    if env_irradiance is not None and not np.any(kinds == LIGHT_ENVIRONMENT):
        lights = concatenate([lights, _environment_row()])
        kinds = lights.kind
    infinite = flag_rows(kinds, "infinite")
    n = kinds.shape[0]
    n_bounded = int(np.count_nonzero(~infinite))
    if np.any(infinite[:n_bounded]) or np.count_nonzero(kinds == LIGHT_ENVIRONMENT) > 1:
        raise ParameterError("the light table must list its bounded lights first, then at most one environment last")
    if np.any(kinds == LIGHT_ENVIRONMENT) and (kinds[-1] != LIGHT_ENVIRONMENT or env_irradiance is None):
        raise ParameterError("an environment row must be the table's last, with env_irradiance given")
    bounded = LightArrays(*(a[:n_bounded] for a in lights))
    infinite_rows = LightArrays(*(a[n_bounded:] for a in lights))
    inf_a, inf_b, inf_floor = (
        np.ascontiguousarray(np.stack(pair))
        for pair in zip(
            _infinite_terms(infinite_rows, env), _infinite_terms(infinite_rows, env_compensated), strict=True
        )
    )
    trail = np.zeros(0, np.int64)
    wide_bounds, wide_child = np.zeros((0, BOUNDS_WIDTH * WIDTH)), np.zeros((0, WIDTH), np.int64)
    cdf = np.zeros(0)
    if mode == "uniform":
        nodes = _no_nodes()
    elif mode in ("bvh", "learned"):
        nodes, m = _build_bvh(bounded)
        if m > 0:
            wide_bounds, wide_child, trail, deepest = _collapse(
                _bounds_rows(nodes), nodes["second"], nodes["light"], n_bounded
            )
            assert TRAIL_BITS * (deepest + 1) <= 63, deepest  # _collapse: at most 21 levels of a 62-level tree
        nodes = {k: v[:1] for k, v in nodes.items()}  # the root's bounds: the environment's share
    else:
        phi = power_of_lights(bounded)
        weights = phi if phi.sum() > 0 else np.ones(n_bounded)
        cdf = np.concatenate([[0.0], np.cumsum(weights) / weights.sum()]) if n_bounded else np.zeros(0)
        if n_bounded:
            cdf[-1] = 1.0
        nodes = _root_only(bounded)
    return LightSelector(
        SELECTORS[mode],
        n,
        n_bounded,
        n - 1 if n and kinds[-1] == LIGHT_ENVIRONMENT else -1,
        inf_a,
        inf_b,
        inf_floor,
        cdf,
        _bounds_rows(nodes),
        wide_bounds,
        wide_child,
        trail,
        *NOT_LEARNED,
    )


#: the learned fields of a selector that has learned nothing (LightSelector's last seven fields)
NOT_LEARNED = (
    0,
    np.zeros(0, np.int64),
    np.zeros(0, np.int64),
    np.zeros(0),
    np.zeros((0, 2), np.int64),
    np.zeros((0, 1)),
    1.0,
)


def _bounds_rows(nodes: dict) -> np.ndarray:
    """The nodes' bounds as rows of ``LightSelector.node_bounds``."""
    rows = np.zeros((nodes["phi"].shape[0], BOUNDS_WIDTH))
    rows[:, B_CENTER : B_CENTER + 3] = 0.5 * (nodes["lo"] + nodes["hi"])
    rows[:, B_RADIUS] = 0.5 * np.linalg.norm(nodes["hi"] - nodes["lo"], axis=1)
    rows[:, B_AXIS : B_AXIS + 3] = nodes["w"]
    rows[:, B_COS_O] = nodes["cos_o"]
    rows[:, B_SIN_O] = np.sqrt(np.maximum(0.0, 1.0 - nodes["cos_o"] ** 2))
    rows[:, B_COS_E] = nodes["cos_e"]
    rows[:, B_PHI] = nodes["phi"]
    rows[:, B_TWO_SIDED] = nodes["two"]
    return rows


def _environment_row() -> LightArrays:
    return LightArrays(
        np.array([LIGHT_ENVIRONMENT], np.int64), np.zeros((1, ROW_WIDTH)), np.zeros((1, 3)), np.zeros(1, np.int64),
        np.zeros(1),
    )  # fmt: skip


def _irradiance_terms(terms, name: str) -> np.ndarray:
    """(a, bx, by, bz) as float64, checked: 4 finite numbers with a >= 0 (zeros for None)."""
    env = np.zeros(4) if terms is None else np.asarray(terms, dtype=np.float64).reshape(4)
    if not np.all(np.isfinite(env)) or env[0] < 0:
        raise ParameterError(f"{name} must be 4 finite numbers with a >= 0, got {terms!r}")
    return env


def _infinite_terms(infinite: LightArrays, env: np.ndarray):
    """(a, b, floor) of each infinite light's irradiance on a receiver with normal n, max(a + b . n, floor): the
    environment's first-order terms (floored at a / 4), a directional light's E n . w_l (floored at E / 4)."""
    k = infinite.kind.shape[0]
    a, b, floor = np.zeros(k), np.zeros((k, 3)), np.zeros(k)
    for i in range(k):
        if infinite.kind[i] == LIGHT_ENVIRONMENT:
            a[i], b[i], floor[i] = env[0], env[1:], 0.25 * env[0]
        else:  # directional: its irradiance at normal incidence is E (kept in radiance at angle 0, else pi L sin^2)
            g = infinite.geom[i]
            sin2 = g[4] * (2.0 - g[4])  # 1 - cos^2 alpha from 1 - cos alpha
            e = float(luminance(infinite.radiance[i])) * (1.0 if g[4] <= 0.0 else math.pi * sin2)
            b[i], floor[i] = e * g[0:3], 0.25 * e
    return a, np.ascontiguousarray(b), floor


def _no_nodes() -> dict:
    return _root_nodes(0)


def _root_nodes(m: int) -> dict:
    return {
        "lo": np.zeros((m, 3)),
        "hi": np.zeros((m, 3)),
        "phi": np.zeros(m),
        "w": np.zeros((m, 3)),
        "cos_o": np.ones(m),
        "cos_e": np.zeros(m),
        "two": np.zeros(m, np.int64),
        "second": np.full(m, -1, np.int64),
        "light": np.full(m, -1, np.int64),
    }


def _root_only(lights: LightArrays) -> dict:
    """The bounds of every emitting area light as one node (the environment's share, ``env_probability``): box and
    power summed, and a cone about the mean normal wide enough for every normal (not the smallest one, which the
    BVH's unions find: this takes O(L) vector operations at 100,000 lights)."""
    if lights.kind.shape[0] == 0:
        return _no_nodes()
    lo, hi, phi, w, cos_o, cos_e, two = _light_bounds(lights)
    on = phi > 0
    if not on.any():
        return _no_nodes()
    nodes = _root_nodes(1)
    nodes["lo"][0], nodes["hi"][0] = lo[on].min(axis=0), hi[on].max(axis=0)
    nodes["phi"][0] = phi[on].sum()
    nodes["cos_e"][0] = cos_e[on].min()
    nodes["two"][0] = int(two[on].max())
    mean = w[on].sum(axis=0)
    length = float(np.linalg.norm(mean))
    if np.all(cos_o[on] >= 1.0) and length > 1e-9 * on.sum():
        axis = mean / length
        nodes["w"][0] = axis
        nodes["cos_o"][0] = max(-1.0, float((w[on] @ axis).min()) - 1e-9)
    else:  # spheres (normals everywhere) or normals that cancel: every direction
        nodes["w"][0] = (0.0, 0.0, 1.0)
        nodes["cos_o"][0] = -1.0
    return nodes


class LightSampler:
    """A selector usable from Python: ``select(points, normals, u) -> (lights, pmf)`` (with ``rescaled=True`` also
    each u rescaled to [0, 1) within the interval that chose its light), ``pmf(point, normal)`` (the probability of
    every light for one receiver), ``pmf_of(points, normals, lights)`` (each receiver's probability of one light);
    ``compensated=True`` for a receiver whose material samples the MIS-compensated
    environment (weighed by ``env_irradiance_compensated``)."""

    def __init__(self, mode: str, lights: LightArrays, *, env_irradiance=None, env_irradiance_compensated=None):
        self.mode = mode
        self.arrays = build_selector(
            mode, lights, env_irradiance=env_irradiance, env_irradiance_compensated=env_irradiance_compensated
        )

    def select(self, points, normals, u, *, rescaled: bool = False, compensated: bool = False):
        u = np.ascontiguousarray(np.asarray(u, dtype=np.float64).reshape(-1))
        points, normals = read_only_rows(points, u.size), read_only_rows(normals, u.size)
        light, pmf, rest = _select_batch(self.arrays, points, normals, u, bool(compensated))
        return (light, pmf, rest) if rescaled else (light, pmf)

    def pmf_of(self, points, normals, lights, *, compensated: bool = False) -> np.ndarray:
        """(N,) the probability that :meth:`select` picks ``lights[i]`` for receiver i."""
        lights = np.ascontiguousarray(np.asarray(lights, dtype=np.int64).reshape(-1))
        points, normals = read_only_rows(points, lights.size), read_only_rows(normals, lights.size)
        return _pmf_rows(self.arrays, points, normals, lights, bool(compensated))

    def pmf(self, point, normal, *, compensated: bool = False) -> np.ndarray:
        # fresh copies: one array type for the kernel whatever the caller passed
        return _pmf_all(
            self.arrays, np.array(point, dtype=np.float64), np.array(normal, dtype=np.float64), bool(compensated)
        )
