"""Choosing which light to sample: uniform, in proportion to power, or with a light BVH.

The lecture's many-light estimator picks light l with probability p_l and divides by it (1/(KN) sum f / (p_l p)),
so every selector offers ``select(p, n, u) -> (light, pmf)`` and ``pmf(p, n, light)`` for MIS (pbrt-v4's
``LightSampler::Sample / PMF``).  Lights are numbered as in the scene's light table; when the scene has an
environment map it is one more light, the last index.

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
    phi cos(theta') / d^2 times the bound on the cosine at the receiver (pbrt-v4's ``LightBounds::Importance``).
    O(depth) per pick and per pmf.  The environment is picked first with probability equal to its share of the
    total power (as ``power`` would), the BVH otherwise.  Nodes split at the median centroid along the axis of
    largest extent (pbrt-v4 uses a surface-area-orientation cost; the median split is simpler and keeps the tree
    balanced: depth ceil(log2 L)).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._numba import jit, jit_parallel, prange
from ..color import luminance
from ..errors import ParameterError
from .area import LIGHT_RECT, LIGHT_SPHERE, LIGHT_TRIANGLE, LightArrays

__all__ = [
    "SELECTORS",
    "LightSampler",
    "LightSelector",
    "build_selector",
    "power_of_lights",
    "select_light",
    "selector_pmf",
]

SELECTORS = {"uniform": 0, "power": 1, "bvh": 2}
UNIFORM, POWER, BVH = 0, 1, 2
MAX_DEPTH = 62  # bit trails are int64


class LightSelector(NamedTuple):
    """Arrays the kernels read.  Node arrays are empty unless ``mode == BVH``."""

    mode: int
    n_lights: int  # area lights + the environment (if any)
    env_index: int  # -1: no environment
    p_env: float  # BVH mode: probability of picking the environment
    cdf: np.ndarray  # (n_lights + 1,) power CDF (POWER), empty otherwise
    node_lo: np.ndarray  # (M, 3) bounds of each node
    node_hi: np.ndarray
    node_phi: np.ndarray  # (M,) power
    node_w: np.ndarray  # (M, 3) axis of the normal cone
    node_cos_o: np.ndarray  # (M,) cos of the normal cone's spread
    node_cos_e: np.ndarray  # (M,) cos of the emission spread about any normal
    node_two_sided: np.ndarray  # (M,) int64
    node_second: np.ndarray  # (M,) index of the second child (the first is node + 1); -1 for a leaf
    node_light: np.ndarray  # (M,) the light of a leaf, -1 otherwise
    light_trail: np.ndarray  # (n_area,) bit trail from the root to each light's leaf (bit d: 1 = second child)


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
    phi = power_of_lights(lights)
    return lo, hi, phi, w, cos_o, cos_e, lights.two_sided.astype(np.int64)


def power_of_lights(lights: LightArrays) -> np.ndarray:
    """Emitted power (of the luminance) of each area light: pi A L, doubled for two-sided lights."""
    return math.pi * lights.area * luminance(lights.radiance) * np.where(lights.two_sided == 1, 2.0, 1.0)


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    d = float(np.dot(a, b))
    if d < 0:
        return math.pi - 2 * math.asin(min(1.0, float(np.linalg.norm(a + b)) / 2))
    return 2 * math.asin(min(1.0, float(np.linalg.norm(b - a)) / 2))


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation of v about the unit axis."""
    c, s = math.cos(angle), math.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1 - c)


def _cone_union(wa, cos_a, wb, cos_b):
    """The smallest cone (pbrt-v4 DirectionCone Union) holding both cones."""
    theta_a, theta_b = math.acos(max(-1.0, min(1.0, cos_a))), math.acos(max(-1.0, min(1.0, cos_b)))
    theta_d = _angle_between(wa, wb)
    if min(theta_d + theta_b, math.pi) <= theta_a:
        return wa, cos_a
    if min(theta_d + theta_a, math.pi) <= theta_b:
        return wb, cos_b
    theta_o = (theta_a + theta_d + theta_b) / 2
    if theta_o >= math.pi:
        return np.array([0.0, 0.0, 1.0]), -1.0
    wr = np.cross(wa, wb)
    if np.dot(wr, wr) == 0:
        return np.array([0.0, 0.0, 1.0]), -1.0
    w = _rotate(wa, wr / np.linalg.norm(wr), theta_o - theta_a)
    return w / np.linalg.norm(w), math.cos(theta_o)


def _build_bvh(lights: LightArrays):
    lo, hi, phi, w, cos_o, cos_e, two = _light_bounds(lights)
    n = lo.shape[0]
    emitting = np.nonzero(phi > 0)[0]  # a light with no power is never picked (its pmf is 0)
    m = max(1, 2 * emitting.size - 1)
    nodes = {
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
    trail = np.zeros(n, np.int64)
    if emitting.size == 0:
        return nodes, trail, 0
    centroid = 0.5 * (lo + hi)
    count = 0
    # explicit stack of (light indices, node index to fill, depth, trail bits)
    stack = [(emitting, 0, 0, 0)]
    count = 1
    while stack:
        idx, node, depth, bits = stack.pop()
        nodes["lo"][node] = lo[idx].min(axis=0)
        nodes["hi"][node] = hi[idx].max(axis=0)
        nodes["phi"][node] = phi[idx].sum()
        nodes["two"][node] = int(two[idx].max())
        nodes["cos_e"][node] = cos_e[idx].min()
        if idx.size == 1:
            light = int(idx[0])
            nodes["light"][node] = light
            nodes["w"][node] = w[light]
            nodes["cos_o"][node] = cos_o[light]
            trail[light] = bits
            continue
        if depth >= MAX_DEPTH:
            raise ParameterError(f"light BVH deeper than {MAX_DEPTH} levels ({n} lights)")
        c = centroid[idx]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = idx[np.argsort(c[:, axis], kind="stable")]
        half = order.size // 2
        left, right = order[:half], order[half:]
        first, second = node + 1, node + 2 * left.size  # the first subtree has 2|left| - 1 nodes
        nodes["second"][node] = second
        stack.append((right, second, depth + 1, bits | (1 << depth)))
        stack.append((left, first, depth + 1, bits))
        count += 2
    # normal cones bottom-up (children have larger indices than their parent)
    for node in range(m - 1, -1, -1):
        second = nodes["second"][node]
        if second < 0:
            continue
        wa, ca = _cone_union(nodes["w"][node + 1], nodes["cos_o"][node + 1], nodes["w"][second], nodes["cos_o"][second])
        nodes["w"][node], nodes["cos_o"][node] = wa, ca
    return nodes, trail, count


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


@jit
def node_importance(sel, i, px, py, pz, nx, ny, nz):
    """pbrt-v4 LightBounds::Importance of node i for a receiver at p with normal n."""
    lo, hi = sel.node_lo[i], sel.node_hi[i]
    cx, cy, cz = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])
    dx, dy, dz = px - cx, py - cy, pz - cz
    d2 = dx * dx + dy * dy + dz * dz
    diag = math.sqrt((hi[0] - lo[0]) ** 2 + (hi[1] - lo[1]) ** 2 + (hi[2] - lo[2]) ** 2)
    d2 = max(d2, 0.5 * diag)
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist > 0.0:
        wx, wy, wz = dx / dist, dy / dist, dz / dist
    else:
        wx, wy, wz = 0.0, 0.0, 1.0
    w = sel.node_w[i]
    cos_w = w[0] * wx + w[1] * wy + w[2] * wz
    if sel.node_two_sided[i] == 1:
        cos_w = abs(cos_w)
    sin_w = math.sqrt(max(0.0, 1.0 - cos_w * cos_w))
    # directions subtended by the box's bounding sphere
    radius = 0.5 * diag
    if dist * dist <= radius * radius:
        cos_b = -1.0
    else:
        cos_b = math.sqrt(max(0.0, 1.0 - radius * radius / (dist * dist)))
    sin_b = math.sqrt(max(0.0, 1.0 - cos_b * cos_b))
    cos_o = sel.node_cos_o[i]
    sin_o = math.sqrt(max(0.0, 1.0 - cos_o * cos_o))
    cos_x = _cos_sub_clamped(sin_w, cos_w, sin_o, cos_o)
    sin_x = _sin_sub_clamped(sin_w, cos_w, sin_o, cos_o)
    cos_p = _cos_sub_clamped(sin_x, cos_x, sin_b, cos_b)
    if cos_p <= sel.node_cos_e[i]:
        return 0.0
    importance = sel.node_phi[i] * cos_p / d2
    if nx != 0.0 or ny != 0.0 or nz != 0.0:
        cos_i = abs(wx * nx + wy * ny + wz * nz)
        sin_i = math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
        importance *= _cos_sub_clamped(sin_i, cos_i, sin_b, cos_b)
    return max(importance, 0.0)


@jit
def _child_weights(sel, a, b, px, py, pz, nx, ny, nz):
    """Importances of children a and b; where both are zero (the parent's looser bound let the descent reach a
    subtree that cannot light the receiver), their powers instead, so that the pmf over all lights sums to one
    (pbrt-v4 returns no light there; either way the sample contributes nothing and nothing is biased)."""
    ia = node_importance(sel, a, px, py, pz, nx, ny, nz)
    ib = node_importance(sel, b, px, py, pz, nx, ny, nz)
    if ia == 0.0 and ib == 0.0:
        return sel.node_phi[a], sel.node_phi[b]
    return ia, ib


@jit
def select_light(sel, px, py, pz, nx, ny, nz, u):
    """(light index, probability) for a receiver at p with normal n; (-1, 0) when no light can be picked."""
    if sel.n_lights == 0:
        return -1, 0.0
    if sel.mode == UNIFORM:
        return min(int(u * sel.n_lights), sel.n_lights - 1), 1.0 / sel.n_lights
    if sel.mode == POWER:
        cdf = sel.cdf
        lo, hi = 0, cdf.shape[0] - 2
        while lo < hi:  # the first bin whose upper edge exceeds u
            mid = (lo + hi) // 2
            if cdf[mid + 1] <= u:
                lo = mid + 1
            else:
                hi = mid
        p = cdf[lo + 1] - cdf[lo]
        return lo, p
    # BVH
    pmf = 1.0
    if sel.env_index >= 0:
        if u < sel.p_env or sel.node_phi.shape[0] == 0 or sel.node_phi[0] <= 0.0:
            return (sel.env_index, sel.p_env) if sel.p_env > 0.0 else (-1, 0.0)
        pmf = 1.0 - sel.p_env
        u = min((u - sel.p_env) / pmf, 1.0 - 1e-16)
    if sel.node_phi.shape[0] == 0 or sel.node_phi[0] <= 0.0:
        return -1, 0.0
    node = 0
    while sel.node_second[node] >= 0:
        a = node + 1
        b = sel.node_second[node]
        ia, ib = _child_weights(sel, a, b, px, py, pz, nx, ny, nz)
        pa = ia / (ia + ib)
        if u < pa:
            node = a
            pmf *= pa
            u = min(u / pa, 1.0 - 1e-16)
        else:
            node = b
            pmf *= ib / (ia + ib)  # the very expression selector_pmf uses, so both report the same bits
            u = min((u - pa) / (1.0 - pa), 1.0 - 1e-16)
    return sel.node_light[node], pmf


@jit
def selector_pmf(sel, px, py, pz, nx, ny, nz, light):
    """Probability that :func:`select_light` picks ``light`` for this receiver."""
    if light < 0 or light >= sel.n_lights:
        return 0.0
    if sel.mode == UNIFORM:
        return 1.0 / sel.n_lights
    if sel.mode == POWER:
        return sel.cdf[light + 1] - sel.cdf[light]
    if light == sel.env_index:
        return sel.p_env
    pmf = 1.0 - sel.p_env if sel.env_index >= 0 else 1.0
    if sel.node_phi.shape[0] == 0 or sel.node_phi[0] <= 0.0:
        return 0.0
    bits = sel.light_trail[light]
    node = 0
    depth = 0
    while sel.node_second[node] >= 0:
        a = node + 1
        b = sel.node_second[node]
        ia, ib = _child_weights(sel, a, b, px, py, pz, nx, ny, nz)
        if (bits >> depth) & 1:
            pmf *= ib / (ia + ib)
            node = b
        else:
            pmf *= ia / (ia + ib)
            node = a
        depth += 1
    return pmf if sel.node_light[node] == light else 0.0


@jit_parallel
def _select_batch(sel, points, normals, u):
    n = u.shape[0]
    light = np.empty(n, np.int64)
    pmf = np.empty(n)
    for i in prange(n):
        light[i], pmf[i] = select_light(
            sel, points[i, 0], points[i, 1], points[i, 2], normals[i, 0], normals[i, 1], normals[i, 2], u[i]
        )
    return light, pmf


@jit_parallel
def _pmf_all(sel, p, n):
    out = np.empty(sel.n_lights)
    for light in prange(sel.n_lights):
        out[light] = selector_pmf(sel, p[0], p[1], p[2], n[0], n[1], n[2], light)
    return out


# --- construction ----------------------------------------------------------------------------------------------------
def build_selector(mode: str, lights: LightArrays, *, env_power: float | None = None) -> LightSelector:
    """A selector over ``lights`` plus, if ``env_power`` is given, the environment as the last light."""
    if mode not in SELECTORS:
        raise ParameterError(f"light sampler must be one of {list(SELECTORS)}, got {mode!r}")
    n_area = lights.kind.shape[0]
    has_env = env_power is not None
    n = n_area + int(has_env)
    phi = power_of_lights(lights)
    total = float(phi.sum()) + (float(env_power) if has_env else 0.0)
    empty2 = np.zeros((0, 3))
    empty1 = np.zeros(0)
    emptyi = np.zeros(0, np.int64)
    cdf = empty1
    p_env = 0.0
    if has_env:
        p_env = float(env_power) / total if total > 0 else 1.0
    if mode == "power":
        weights = np.concatenate([phi, [float(env_power)]]) if has_env else phi
        if not weights.sum() > 0:
            weights = np.ones(n)
        cdf = np.concatenate([[0.0], np.cumsum(weights) / weights.sum()])
        cdf[-1] = 1.0
    if mode == "bvh":
        nodes, trail, _ = _build_bvh(lights)
        return LightSelector(
            SELECTORS[mode],
            n,
            n_area if has_env else -1,
            p_env,
            cdf,
            nodes["lo"],
            nodes["hi"],
            nodes["phi"],
            nodes["w"],
            nodes["cos_o"],
            nodes["cos_e"],
            nodes["two"],
            nodes["second"],
            nodes["light"],
            trail,
        )
    return LightSelector(
        SELECTORS[mode],
        n,
        n_area if has_env else -1,
        p_env,
        cdf,
        empty2,
        empty2,
        empty1,
        empty2,
        empty1,
        empty1,
        emptyi,
        emptyi,
        emptyi,
        emptyi,
    )


class LightSampler:
    """A selector usable from Python: ``select(points, normals, u) -> (lights, pmf)``, ``pmf(point, normal)`` (the
    probability of every light for one receiver)."""

    def __init__(self, mode: str, lights: LightArrays, *, env_power: float | None = None):
        self.mode = mode
        self.arrays = build_selector(mode, lights, env_power=env_power)

    def select(self, points, normals, u):
        u = np.ascontiguousarray(np.asarray(u, dtype=np.float64).reshape(-1))
        points = np.ascontiguousarray(np.broadcast_to(np.asarray(points, dtype=np.float64), (u.size, 3)))
        normals = np.ascontiguousarray(np.broadcast_to(np.asarray(normals, dtype=np.float64), (u.size, 3)))
        return _select_batch(self.arrays, points, normals, u)

    def pmf(self, point, normal) -> np.ndarray:
        return _pmf_all(self.arrays, np.asarray(point, dtype=np.float64), np.asarray(normal, dtype=np.float64))
