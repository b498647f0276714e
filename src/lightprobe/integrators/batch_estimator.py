"""The estimator at a batch of shading points, from techniques that draw whole batches of directions: the one the
laboratory renders with (:mod:`lightprobe.lab.render`, user techniques in NumPy or compiled) and the one the
shading-point tables measure with (:mod:`lightprobe.integrators.shading_point`).

At each point k, seen from ``wo`` with material f, lit by the environment L (Krivanek eqs. 2 and 16)::

    value(k) = sum over techniques t, samples i of  w_t(wi) f(wo, wi) cos(theta_i) L(wi) V(wi) / (n_t p_t(wi))

with w_t the MIS weight against the other technique (1 for a technique alone), n_t its samples per point and p_t
its density.  A technique draws its ``n_t x N`` directions in one call (row r: sample r // N of point r % N), in
the local frame (a BSDF technique) or the world (a light technique); :func:`add_samples` then evaluates f, offsets
each live row's shadow ray as the render core does (``integrators.techniques.store_shading_frame``'s error bound
along the geometric normal), asks ``occluded`` and adds the visible rows to their points sample by sample, in the
order the core adds them, so that lightprobe's own techniques give the core's image bit for bit.  Whatever draws
the directions (a user's NumPy method, a compiled loop, lightprobe's own samplers) the terms after it are these.

:class:`Context` is what a technique sees of the batch; :class:`MaterialSampling`, :class:`EnvironmentSampling`
and :class:`HemisphereSampling` are lightprobe's own techniques behind the user techniques' contract
(``lab/techniques.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._numba import jit_parallel, prange
from ..bsdfs.dispatch import bsdf_eval
from ..emitters.envmap import env_eval
from ..sampling import warps

__all__ = [
    "Context",
    "EnvironmentSampling",
    "HemisphereSampling",
    "MaterialSampling",
    "add_samples",
    "directions",
    "shade",
]

#: occluded(origins (M, 3), unit directions (M, 3)) -> (M,) True where something blocks the ray
Occluded = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Context:
    """The shading points of one batch, as a technique sees them (N points).

    Attributes
    ----------
    wo : (N, 3)
        Direction toward the viewer in the local shading frame (normal +z).
    normal : (N, 3)
        Shading normal, world space.
    frame : (N, 3, 3)
        Rows s, t, n of the shading frame in world space: ``local = frame @ world``, ``world = local @ frame``.
    position : (N, 3)
        Hit points, world space.
    material : lightprobe BSDF
        The batch's material (one per batch), e.g. :class:`lightprobe.Phong` with ``rho_d``, ``rho_s`` (RGB arrays),
        ``exponent``; its own ``eval``, ``pdf`` and ``sample`` are there too.
    environment : lightprobe EnvironmentMap or None
        The map: ``luminance`` (H, W) of the texels (lat-long, row 0 the zenith), ``radiance`` (H, W, 3),
        ``to_world`` (3 x 3, the map's rotation), ``eval(dirs)``. ``lightprobe.lab.uv_to_direction`` and
        ``direction_to_uv`` convert between lat-long (u, v) and world directions with its rotation.
    """

    wo: np.ndarray
    normal: np.ndarray
    frame: np.ndarray
    position: np.ndarray
    material: object = None
    environment: object = None

    def __len__(self) -> int:
        return self.wo.shape[0]

    def subset(self, rows) -> Context:
        """The context of some of the points (a boolean mask or indices)."""
        return Context(self.wo[rows], self.normal[rows], self.frame[rows], self.position[rows], self.material,
                       self.environment)  # fmt: skip

    @classmethod
    def local(cls, wo, n: int, material=None, environment=None) -> Context:
        """N copies of one local ``wo`` at the origin with normal +z (world = local): what ``check`` uses."""
        w = np.asarray(wo, dtype=np.float64).reshape(3)
        w = w / np.linalg.norm(w)
        frame = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        return cls(np.tile(w, (n, 1)), np.tile([0.0, 0.0, 1.0], (n, 1)), frame, np.zeros((n, 3)), material,
                   environment)  # fmt: skip

    @classmethod
    def at_point(cls, wo, frame, n: int, material=None, environment=None) -> Context:
        """N copies of one point at the origin, its shading frame's rows ``frame`` (s, t, n in world space), seen
        from the local direction ``wo`` (unit): the shading-point tables' setting.  The frames, normals and
        positions are read-only views of one row."""
        rows = np.asarray(frame, dtype=np.float64).reshape(3, 3)
        return cls(np.tile(np.asarray(wo, dtype=np.float64).reshape(3), (n, 1)), np.broadcast_to(rows[2], (n, 3)),
                   np.broadcast_to(rows, (n, 3, 3)), np.broadcast_to(np.zeros(3), (n, 3)), material,
                   environment)  # fmt: skip


# --- lightprobe's own techniques, behind the user techniques' contract ----------------------------------------------
class MaterialSampling:
    """The material's own importance sampling (its ``sample``/``pdf``, lobes chosen by u[:, 2])."""

    kind = "bsdf"
    dimensions = 3
    support = "sphere"

    def sample(self, u, ctx):
        # the materials take their 2D pair from columns 1 and 2 (bsdfs/base.py); a technique's u has it in 0 and 1
        return ctx.material.sample(ctx.wo, np.ascontiguousarray(u[:, [2, 0, 1]]))

    def pdf(self, wi, ctx):
        return ctx.material.pdf(ctx.wo, wi)


class EnvironmentSampling:
    """The environment map's own importance sampling (its ``sample``/``pdf``); ``compensated``: its MIS-compensated
    density (zero on dim texels, so only under MIS with BSDF samples)."""

    kind = "light"
    dimensions = 2
    support = "sphere"

    def __init__(self, compensated: bool = False):
        self.compensated = compensated

    def sample(self, u, ctx):
        return ctx.environment.sample(u, compensated=self.compensated)

    def pdf(self, wi, ctx):
        return ctx.environment.pdf(wi, compensated=self.compensated)


class HemisphereSampling:
    """Directions uniform on the hemisphere about the normal (pdf 1 / (2 pi)) or cosine-weighted (pdf cos / pi)."""

    kind = "bsdf"
    dimensions = 2
    support = "hemisphere"

    def __init__(self, cosine: bool):
        self.cosine = cosine

    def sample(self, u, ctx):
        if self.cosine:
            wi = warps.square_to_cosine_hemisphere(u)
        else:
            wi = warps.square_to_uniform_hemisphere(u)
        return wi, self.pdf(wi, ctx)

    def pdf(self, wi, ctx):
        return warps.cosine_hemisphere_pdf(wi) if self.cosine else warps.uniform_hemisphere_pdf(wi)


# --- the terms after the directions: one place for the estimator -----------------------------------------------------
@jit_parallel
def _sample_terms(kind, params, count, wo, gnormal, error, position, local, world, pdf, weight, f, scale, d, origin,
                  live):  # fmt: skip
    """Each row's f, its factor w cos / (n p), its unit direction and the offset origin of its shadow ray, where the
    row is live (pdf, cos, weight and f all > 0)."""
    n = wo.shape[0]
    for r in prange(pdf.shape[0]):
        k = r % n
        fr, fg, fb = bsdf_eval(kind, params, (wo[k, 0], wo[k, 1], wo[k, 2]), (local[r, 0], local[r, 1], local[r, 2]))
        f[r, 0], f[r, 1], f[r, 2] = fr, fg, fb
        cos = max(local[r, 2], 0.0)
        live[r] = pdf[r] > 0.0 and cos > 0.0 and weight[r] > 0.0 and (fr > 0.0 or fg > 0.0 or fb > 0.0)
        if live[r]:
            x, y, z = world[r, 0], world[r, 1], world[r, 2]
            norm = np.sqrt(x * x + y * y + z * z)
            x, y, z = x / norm, y / norm, z / norm
            d[r, 0], d[r, 1], d[r, 2] = x, y, z
            ng0, ng1, ng2 = gnormal[k, 0], gnormal[k, 1], gnormal[k, 2]
            side = -1.0 if x * ng0 + y * ng1 + z * ng2 < 0.0 else 1.0
            offset = side * error[k]
            origin[r, 0] = position[k, 0] + offset * ng0
            origin[r, 1] = position[k, 1] + offset * ng1
            origin[r, 2] = position[k, 2] + offset * ng2
            scale[r] = weight[r] * cos / (count * pdf[r])


@jit_parallel
def _add_visible(env, count, out, f, scale, d, visible):
    """out[k] += f L(d) w cos / (n p) of each visible row, sample by sample in order."""
    n = out.shape[0]
    for k in prange(n):
        for i in range(count):
            r = i * n + k
            if visible[r]:
                lr, lg, lb = env_eval(env, d[r, 0], d[r, 1], d[r, 2])
                out[k, 0] += f[r, 0] * lr * scale[r]
                out[k, 1] += f[r, 1] * lg * scale[r]
                out[k, 2] += f[r, 2] * lb * scale[r]
            else:  # a row of zeros, as a sum of every row adds (it turns -0.0 into 0.0)
                out[k, 0] += 0.0
                out[k, 1] += 0.0
                out[k, 2] += 0.0


def add_samples(out, ctx: Context, count: int, local, world, pdf, weight, gnormal, error, occluded: Occluded) -> int:
    """Add one technique's ``count x N`` rows (directions ``local`` and ``world``, densities ``pdf``, MIS weights
    ``weight``) to ``out`` (N, 3), the estimator of the module docstring, with visibility from ``occluded``; returns
    the shadow rays it asked about."""
    m = pdf.shape[0]
    count = int(count)  # one compiled version of the kernels whatever type of integer the caller has
    material = ctx.material
    f, scale, d, origin = np.empty((m, 3)), np.zeros(m), np.zeros((m, 3)), np.zeros((m, 3))
    live = np.zeros(m, dtype=np.bool_)
    _sample_terms(material.kind, material.params, count, np.ascontiguousarray(ctx.wo), gnormal, error,
                  np.ascontiguousarray(ctx.position), np.ascontiguousarray(local), np.ascontiguousarray(world),
                  np.ascontiguousarray(pdf), np.ascontiguousarray(weight), f, scale, d, origin, live)  # fmt: skip
    rows = np.nonzero(live)[0]
    visible = np.zeros(m, dtype=np.bool_)
    if rows.size:
        visible[rows] = ~np.asarray(occluded(origin[rows], d[rows]), dtype=np.bool_)
    _add_visible(ctx.environment.kernel, count, out, f, scale, d, visible)
    return int(rows.size)


def directions(technique, u: np.ndarray, every: Context) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A NumPy technique's directions for the rows of ``every`` (u: one row of numbers each), in both frames:
    (local, world, pdf)."""
    wi, pdf = technique.sample(u, every)
    if technique.kind == "bsdf":
        return wi, np.einsum("nk,nkj->nj", wi, every.frame), pdf
    return np.einsum("nkj,nj->nk", every.frame, wi), wi, pdf


def shade(ctx: Context, techniques, counts, weight, numbers, gnormal, error, occluded: Occluded):
    """The estimator at the points of ``ctx`` (one material) from NumPy techniques: ``counts[t]`` samples per point
    of technique t, drawn from ``numbers[t]`` (count, N, dims); two techniques are combined by MIS with
    ``weight(n_f, p_f, n_g, p_g)`` (arrays of weights).  Each technique is called once for all its samples (count x
    N rows, sample-major).  Returns (values (N, 3), shadow rays asked about)."""
    n = len(ctx)
    out = np.zeros((n, 3))
    rays = 0
    for j, (tech, count) in enumerate(zip(techniques, counts, strict=True)):
        every = ctx.subset(np.tile(np.arange(n), count)) if count > 1 else ctx
        local, world, pdf = directions(tech, np.ascontiguousarray(numbers[j].reshape(count * n, -1)), every)
        w = np.ones(count * n)
        if len(techniques) == 2:
            other = techniques[1 - j]
            p_other = other.pdf(local if other.kind == "bsdf" else world, every)
            w = weight(count, pdf, counts[1 - j], p_other)
        rays += add_samples(out, ctx, count, local, world, pdf, w, gnormal, error, occluded)
    return out, rays
