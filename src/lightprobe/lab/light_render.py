"""Render a scene with lights by a light selector, a user's or lightprobe's own: the laboratory's estimator for
scenes lit by area, point, spot, directional and many lights (beside an environment map or without one).

A :class:`SelectorStrategy` takes, per camera sample, ``n_light`` light samples, each light picked by the selector
(``select(ctx, u) -> (light, pmf)``, :mod:`lightprobe.lab.selectors`) and a point on it sampled as the render core
samples it (``emitters.lights.light_sample_of``), and ``n_bsdf`` samples of the material, combined by multiple
importance sampling: with f the material, L the light's radiance and p_l(w) = P(l) p(w | l) the light technique's
density (the lecture's p_l p(x'), per unit solid angle; Veach 1997, eq. 9.3)::

    value = L_e(camera ray)
          + sum over light samples i of  w_l(wi) f(wo, wi) cos(theta_i) L(wi) V(wi) / (n_light P(l_i) p(wi | l_i))
          + sum over BSDF samples j of   w_b(wj) f(wo, wj) cos(theta_j) L(wj) / (n_bsdf p_b(wj))

w the balance or power heuristic of the two densities: a BSDF sample that reaches light l (its emitter, or an
infinite light where it leaves the scene) is weighed against P(l) from the selector's ``pmf(ctx, l)`` times the
light's own density there (``light_pdf_of``); a delta light (point, spot, directional) only the light technique
reaches, with weight 1. Whatever the selector picks, the image stays unbiased where its pmf() is right and every
light it gives probability 0 is one the BSDF samples reach (a point light of probability 0 is lost: the selector's
choice, as in any renderer).

The light samples, their shadow rays and what the BSDF rays see are the render core's routines, compiled
(``light_sample_of``, ``bsdf_eval`` / ``bsdf_pdf``, ``stages.shadows.ray_to_light``, ``emitted``,
``infinite_radiance``, ``light_pdf_of``); the selector is called on NumPy batches (a pass's camera samples of one
batch at a time: ``select`` once per light sample of the batch, ``pmf`` once per light the BSDF rays reached).
Light samples take the plain (uncompensated) environment. Random numbers: camera jitter, then the BSDF samples' group
of shading slots and the light samples' (3 numbers each: the pick, and the pair that samples the light or the BSDF),
a pure function of (seed, pixel, sample index, dimension) as everywhere (``camera_samples.technique_numbers``).

``lightprobe compare SCENE --strategies mis,sel:bvh,sel:FILE.py[:NAME]`` (and ``render --techniques sel:...``)
renders with it: ``sel:uniform``, ``sel:power`` and ``sel:bvh`` are lightprobe's own selectors through this same
estimator, the fair comparison for a user's.
"""

from __future__ import annotations

import math
import warnings
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from numba.core.errors import NumbaIRAssumptionWarning

from .._numba import jit, jit_inline
from ..bsdfs.dispatch import bsdf_eval, bsdf_pdf
from ..bsdfs.dispatch import sample_batch as bsdf_sample_batch
from ..emitters.area import STRATEGIES as LIGHT_STRATEGIES
from ..emitters.kinds import flag_rows
from ..emitters.lights import emitted, first_infinite, infinite_radiance, is_delta, light_pdf_of, light_sample_of
from ..emitters.selection import LightSampler
from ..geometry.frame import to_local
from ..geometry.intersect import MISS, ray_offset, surface
from ..geometry.raytracer import RayTracer
from ..integrators.settings import RenderSettings
from ..integrators.stages.setup import emitter_of
from ..integrators.stages.shadows import ray_to_light
from ..sampling.mis import balance_heuristic, power_heuristic
from ..sampling.rng import SAMPLERS, sampler_batch
from .camera_samples import camera_batch, require_untextured, shading_batch, technique_numbers
from .selectors import GuardedSelector, LightSet, SelectorContext
from .techniques import RenderClock, TechniqueError

__all__ = [
    "BUILTIN_SELECTORS",
    "SelectorStrategy",
    "bsdf_rays",
    "light_sample_rows",
    "quiet_compiling",
    "what_rays_see",
]

#: lightprobe's own selectors a ``sel:`` token names (emitters/selection.py; ``learned`` learns from a render's
#: shadow rays, which this estimator does not keep)
BUILTIN_SELECTORS = ("uniform", "power", "bvh")
#: a user's selector is checked at the shading points of this many random pixels (seeded) before a render
CHECK_POINTS = 64
CHECK_SEED = 11


@dataclass
class SelectorStrategy:
    """Light samples picked by ``selector`` (a :class:`GuardedSelector` or a name of :data:`BUILTIN_SELECTORS`) and
    BSDF samples under MIS with ``heuristic`` (balance or power; None: the render settings')."""

    selector: GuardedSelector | str
    heuristic: str | None = None
    #: no user techniques (``render_lab`` gives theirs the render's clock)
    techniques: tuple = ()

    def __post_init__(self):
        if isinstance(self.selector, str) and self.selector not in BUILTIN_SELECTORS:
            raise TechniqueError(
                f"unknown selector {self.selector!r}: lightprobe's are {', '.join(BUILTIN_SELECTORS)}; or give "
                "FILE.py[:NAME]"
            )
        if self.heuristic not in (None, "balance", "power"):
            raise TechniqueError(
                f"a selector's strategy weighs by the balance or power heuristic, got {self.heuristic!r}"
            )

    @property
    def label(self) -> str:
        return f"sel:{self.selector if isinstance(self.selector, str) else self.selector.label}"

    def counts(self, settings: RenderSettings) -> list[int]:
        """BSDF samples, then light samples, per camera sample."""
        return [settings.n_bsdf, settings.light_samples]


class _CoreSelector:
    """lightprobe's own selector behind the user selectors' contract (select / pmf over a batch): the render core's
    compiled selection (``LightSampler``), for receivers whose material samples the plain environment."""

    def __init__(self, name: str, scene, lights):
        environment = scene.environment
        self.label = name
        self.sampler = LightSampler(
            name, lights, env_irradiance=environment.irradiance_terms if environment is not None else None
        )

    def select(self, ctx: SelectorContext, u: np.ndarray):
        return self.sampler.select(ctx.point, ctx.normal, u)

    def pmf(self, ctx: SelectorContext, light: np.ndarray) -> np.ndarray:
        return self.sampler.pmf_of(ctx.point, ctx.normal, light)


@contextmanager
def quiet_compiling():
    """Numba's SSA pass notes, while compiling :func:`_rays_see`, variables of the inlined light-pdf dispatch it cannot
    place ("an internal pedantic check"): not the user's concern, and the code it compiles is right (the tests
    compare its renders with the core's, and the light choice's split with renders)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaIRAssumptionWarning)
        yield


# --- compiled rows -------------------------------------------------------------------------------------------------
@jit_inline
def light_sample_toward(lights, env, strategy, light, compensated, px, py, pz, nx, ny, nz, frame, wo, kind, params,
                        u0, u1):  # fmt: skip
    """A sample of ``light`` seen from the shading point p (geometric normal n, shading frame ``frame``: rows s, t, n
    flattened; ``wo`` local) and the material there: (whether it gives anything, the light sample, wi local, f)."""
    ls = light_sample_of(lights, env, light, strategy, compensated, px, py, pz, nx, ny, nz, u0, u1)
    if ls.pdf <= 0.0 or (ls.r == 0.0 and ls.g == 0.0 and ls.b == 0.0):
        return False, ls, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0)
    wi = to_local(frame[0:3], frame[3:6], frame[6:9], ls.wx, ls.wy, ls.wz)
    return True, ls, wi, bsdf_eval(kind, params, wo, wi)


@jit_inline
def shadow_ray_toward(lights, light, px, py, pz, nx, ny, nz, error, ls):
    """The shadow ray of light sample ``ls`` (origin, direction, length) from the point p, offset as the core
    offsets it; ending short of the light's surface for a bounded light (``stages.shadows.ray_to_light``)."""
    qx, qy, qz = ray_offset(px, py, pz, nx, ny, nz, error, ls.wx, ls.wy, ls.wz)
    if ls.distance < math.inf:
        return ray_to_light(lights, light, px, py, pz, qx, qy, qz, ls.wx, ls.wy, ls.wz, ls.distance)
    return (qx, qy, qz, ls.wx, ls.wy, ls.wz, math.inf)


@jit
def light_sample_rows(lights, env, strategy, point, gnormal, error, frame, wo, kinds, params, material, compensated,
                      owner, light, u, rgb, pdf, pb, ray):  # fmt: skip
    """Row r: a sample of light ``light[r]`` at point ``owner[r]`` with the numbers u[r, 0:2] (``compensated[i]``:
    point i's material samples the compensated environment): rgb[r] = f L cos / p (unshadowed; 0 where it gives
    nothing), pdf[r] = p, the light's density, pb[r] the BSDF's at the direction (0 for a delta light: its MIS
    weight is 1) and, where rgb > 0, ray[r] its shadow ray (origin, direction, length)."""
    for r in range(light.shape[0]):
        i, row = owner[r], light[r]
        rgb[r, 0] = rgb[r, 1] = rgb[r, 2] = 0.0
        pdf[r] = pb[r] = 0.0
        px, py, pz = point[i, 0], point[i, 1], point[i, 2]
        nx, ny, nz = gnormal[i, 0], gnormal[i, 1], gnormal[i, 2]
        m = material[i]
        w_o = (wo[i, 0], wo[i, 1], wo[i, 2])
        gives, ls, wi, f = light_sample_toward(lights, env, strategy, row, compensated[i], px, py, pz, nx, ny, nz,
                                               frame[i], w_o, kinds[m], params[m], u[r, 0], u[r, 1])  # fmt: skip
        if not gives or wi[2] <= 0.0:
            continue
        scale = wi[2] / ls.pdf
        rgb[r, 0], rgb[r, 1], rgb[r, 2] = f[0] * ls.r * scale, f[1] * ls.g * scale, f[2] * ls.b * scale
        pdf[r] = ls.pdf
        pb[r] = 0.0 if is_delta(lights, row) else bsdf_pdf(kinds[m], params[m], w_o, wi)
        o = shadow_ray_toward(lights, row, px, py, pz, nx, ny, nz, error[i], ls)
        for c in range(7):
            ray[r, c] = o[c]


@jit
def _rays_see(s, lights, env, strategy, point, gnormal, compensated, owner, origins, dirs, weight, hits, light_of,
              value, light_pdf, rgb):  # fmt: skip
    kind, index, prim, b1, b2, t = hits[1], hits[2], hits[3], hits[4], hits[5], hits[0]
    first = first_infinite(lights)
    for r in range(dirs.shape[0]):
        i = owner[r]
        px, py, pz = point[i, 0], point[i, 1], point[i, 2]
        nx, ny, nz = gnormal[i, 0], gnormal[i, 1], gnormal[i, 2]
        wx, wy, wz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
        e = 0
        if kind[r] == MISS:
            for light in range(first, lights.kind.shape[0]):
                lr, lg, lb = infinite_radiance(lights, env, light, wx, wy, wz)
                lum = 0.212671 * weight[r, 0] * lr + 0.715160 * weight[r, 1] * lg + 0.072169 * weight[r, 2] * lb
                if lum > 0.0:
                    light_of[r, e] = light
                    value[r, e] = lum
                    rgb[r, e, 0], rgb[r, e, 1], rgb[r, e, 2] = weight[r, 0] * lr, weight[r, 1] * lg, weight[r, 2] * lb
                    light_pdf[r, e] = light_pdf_of(lights, env, light, strategy, compensated[i], px, py, pz, nx, ny,
                                                   nz, wx, wy, wz)  # fmt: skip
                    e += 1
            continue
        light = emitter_of(s, kind[r], index[r], prim[r])
        if light < 0:
            continue
        x = surface(s, kind[r], index[r], prim[r], b1[r], b2[r], origins[r, 0], origins[r, 1], origins[r, 2], wx, wy,
                    wz, t[r])[0]  # fmt: skip
        lr, lg, lb = emitted(lights, light, x[0], x[1], x[2], wx, wy, wz)
        lum = 0.212671 * weight[r, 0] * lr + 0.715160 * weight[r, 1] * lg + 0.072169 * weight[r, 2] * lb
        if lum > 0.0:
            light_of[r, 0] = light
            value[r, 0] = lum
            rgb[r, 0, 0], rgb[r, 0, 1], rgb[r, 0, 2] = weight[r, 0] * lr, weight[r, 1] * lg, weight[r, 2] * lb
            light_pdf[r, 0] = light_pdf_of(lights, env, light, strategy, compensated[i], px, py, pz, nx, ny, nz, wx,
                                           wy, wz)  # fmt: skip


def what_rays_see(s, lights, env, strategy, point, gnormal, compensated, owner, origins, dirs, weight, hits):
    """For ray r (from point owner[r], ``weight`` its f cos / p): the lights it reaches (the emitter it hits, or
    every infinite light where it leaves the scene), each with lum(weight L), the light's density at the direction
    (for the MIS weight) and weight L itself: arrays (R, E) of light (-1: none), value and density, and (R, E, 3),
    E = the number of infinite lights (at least 1)."""
    n_entries = max(1, int(flag_rows(lights.kind, "infinite").sum()))
    n = dirs.shape[0]
    out = (np.full((n, n_entries), -1, np.int64), np.zeros((n, n_entries)), np.zeros((n, n_entries)),
           np.zeros((n, n_entries, 3)))  # fmt: skip
    _rays_see(s, lights, env, strategy, point, gnormal, compensated, owner, origins, dirs, weight, hits, *out)
    return out


def bsdf_rays(arrays, point, gnormal, error, frame, wo, material, owner, u):
    """Material samples from the points ``owner[r]`` with the numbers u[r] (the materials' layout: the lobe's choice,
    then the pair): (pdf (R,), weight f cos / pdf (R, 3), the rows that give something, their rays' origins, offset as
    the core offsets them (``intersect.ray_offset``), and their unit world directions)."""
    wi, pb, weight = np.zeros((owner.size, 3)), np.zeros(owner.size), np.zeros((owner.size, 3))
    of_owner = material[owner]
    for m in np.unique(of_owner):
        rows = np.flatnonzero(of_owner == m)
        wi[rows], pb[rows], weight[rows] = bsdf_sample_batch(
            arrays.material_kind[m], arrays.material_params[m], np.ascontiguousarray(wo[owner[rows]]), u[rows]
        )
    live = np.flatnonzero((pb > 0.0) & np.any(weight != 0.0, axis=1))
    at = owner[live]
    dirs = np.einsum("ri,rij->rj", wi[live], frame[at].reshape(-1, 3, 3))  # frame rows s, t, n: world = local @ frame
    dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-300)
    ng = gnormal[at]
    side = np.where(np.einsum("ij,ij->i", dirs, ng) < 0.0, -1.0, 1.0)
    origins = point[at] + (side * error[at])[:, None] * ng
    return pb, weight, live, np.ascontiguousarray(origins), np.ascontiguousarray(dirs)


# --- the estimator -------------------------------------------------------------------------------------------------
def check_light_scene(scene) -> None:
    """What a selector's strategy renders: two lights or more (a choice to make), untextured materials."""
    count = scene.light_table().kind.shape[0]
    if count < 2:
        raise TechniqueError(
            f"scene {scene.name!r} has {count} light(s): a light selector's strategy needs two or more to choose from"
        )
    require_untextured(scene, "light selectors")


class LightShader:
    """Everything a selector's render needs between passes (``render_lab``'s shader for a
    :class:`SelectorStrategy`)."""

    compiled = True  # the estimator's loops are compiled; the selector is called on NumPy batches

    def __init__(self, scene, strategy: SelectorStrategy, settings: RenderSettings):
        from ..emitters.envmap import placeholder_environment

        self.scene = scene
        self.strategy = strategy
        self.settings = settings
        self.arrays = scene.compile()
        self.lights = scene.light_table()
        self.env = (scene.environment if scene.environment is not None else placeholder_environment()).kernel
        self.tracer = RayTracer(self.arrays)
        self.cam = scene.camera.kernel_array()
        self.origin = np.asarray(scene.camera.origin, dtype=np.float64)
        self.light_set = LightSet.of(self.lights)
        selector = strategy.selector
        self.selector = _CoreSelector(selector, scene, self.lights) if isinstance(selector, str) else selector
        if not isinstance(selector, str):
            self._check(selector)
        self.n_bsdf, self.n_light = strategy.counts(settings)
        heuristic = strategy.heuristic if strategy.heuristic is not None else settings.heuristic
        self.beta = 1.0 if heuristic == "balance" else 2.0
        self.strategy_code = LIGHT_STRATEGIES[settings.light_strategy]
        self.sampler = SAMPLERS[settings.sampler]
        self.rays = 0
        self.clock = RenderClock(None)

    def close(self):
        self.tracer.close()

    def _check(self, selector: GuardedSelector) -> None:
        """A user's selector checked at the shading points of ``CHECK_POINTS`` random pixels before anything renders
        (``GuardedSelector.pmf_matrix``: pmfs summing to 1, select's pmf = pmf(), picks following pmf()): a selector
        that breaks its contract fails here, in one line, rather than biasing the image."""
        rng = np.random.default_rng(CHECK_SEED)
        width, height = self.scene.camera.resolution
        pixels = np.sort(rng.choice(width * height, min(width * height, CHECK_POINTS), replace=False)).astype(np.int64)
        dirs = camera_batch(self.cam, pixels, rng.random((pixels.size, 2)))
        t, kind, index, prim, b1, b2 = self.tracer.intersect(
            np.ascontiguousarray(np.broadcast_to(self.origin, dirs.shape)), dirs
        )
        point, gnormal, _, _, wo, material = shading_batch(self.arrays, kind, index, prim, b1, b2, t, self.origin, dirs)
        rows = (material >= 0) & (wo[:, 2] > 0.0)
        if rows.any():
            selector.pmf_matrix(point[rows], gnormal[rows], self.lights, seed=CHECK_SEED)

    def _weight(self, n_f, p_f, n_g, p_g) -> np.ndarray:
        if self.beta == 1.0:
            return balance_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)
        return power_heuristic(p_f, p_g, n_f=n_f, n_g=n_g, beta=self.beta)

    def values(self, pixels: np.ndarray, sample: int) -> np.ndarray:
        """Each pixel's value (N, 3) for one sample index."""
        with quiet_compiling():
            return self._values(pixels, sample)

    def _values(self, pixels: np.ndarray, sample: int) -> np.ndarray:
        n = pixels.shape[0]
        seed = self.settings.seed
        jitter = sampler_batch(self.sampler, seed, pixels, np.full(n, sample, dtype=np.int64), 2)
        dirs = camera_batch(self.cam, pixels, jitter)
        origins = np.ascontiguousarray(np.broadcast_to(self.origin, dirs.shape))
        hits = self.tracer.intersect(origins, dirs)
        # what the camera ray sees itself: an emitter's radiance, or the infinite lights' where it leaves the scene
        at_camera = (self.origin[None, :], self.origin[None, :], np.zeros(1, np.bool_), np.zeros(n, np.int64))
        seen = what_rays_see(self.arrays, self.lights, self.env, 0, *at_camera, origins, dirs, np.ones_like(dirs),
                             hits)[3]  # fmt: skip
        value = seen.sum(axis=1)
        t, kind, index, prim, b1, b2 = hits
        point, gnormal, error, frame, wo, material = shading_batch(
            self.arrays, kind, index, prim, b1, b2, t, self.origin, dirs
        )
        rows = np.flatnonzero((material >= 0) & (wo[:, 2] > 0.0))
        if rows.size == 0:
            return value
        numbers = [technique_numbers(self.sampler, seed, pixels, sample, first, count, 3)[:, rows]
                   for first, count in ((0, self.n_bsdf), (self.n_bsdf, self.n_light))]  # fmt: skip
        pts = (np.ascontiguousarray(point[rows]), np.ascontiguousarray(gnormal[rows]), error[rows],
               np.ascontiguousarray(frame[rows]), np.ascontiguousarray(wo[rows]), material[rows])  # fmt: skip
        ctx = SelectorContext(pts[0], pts[1], self.light_set)
        value[rows] += self._light_samples(ctx, pts, numbers[1]) + self._bsdf_samples(ctx, pts, numbers[0])
        return value

    def _light_samples(self, ctx, pts, u) -> np.ndarray:
        """The light samples' share (N, 3): sample i of every point, i = 0 .. n_light - 1, in that order."""
        point, gnormal, error, frame, wo, material = pts
        n = point.shape[0]
        out = np.zeros((n, 3))
        owner = np.arange(n, dtype=np.int64)
        plain = np.zeros(n, np.bool_)  # the plain environment's sampling (not the MIS-compensated one)
        for i in range(self.n_light):
            ui = np.ascontiguousarray(u[i])
            light, pmf = self.selector.select(ctx, ui[:, 0].copy())
            rgb, pdf, pb, ray = np.empty((n, 3)), np.empty(n), np.empty(n), np.empty((n, 7))
            light_sample_rows(self.lights, self.env, self.strategy_code, point, gnormal, error, frame, wo,
                              self.arrays.material_kind, self.arrays.material_params, material, plain, owner,
                              np.ascontiguousarray(light), np.ascontiguousarray(ui[:, 1:3]), rgb, pdf, pb,
                              ray)  # fmt: skip
            live = np.flatnonzero(np.any(rgb > 0.0, axis=1))
            if live.size:
                self.rays += live.size
                seen = ~self.tracer.occluded(ray[live, 0:3], ray[live, 3:6], ray[live, 6])
                live = live[seen]
            if live.size:
                w = self._weight(self.n_light, pmf[live] * pdf[live], self.n_bsdf, pb[live])
                out[live] += rgb[live] * (w / (self.n_light * pmf[live]))[:, None]
        return out

    def _bsdf_samples(self, ctx, pts, u) -> np.ndarray:
        """The BSDF samples' share (N, 3), sample j of every point in order, each weighed against the selector."""
        point, gnormal, error, frame, wo, material = pts
        n = point.shape[0]
        out = np.zeros((n, 3))
        if self.n_bsdf == 0:
            return out
        compensated = np.zeros(n, np.bool_)
        owner = np.arange(n, dtype=np.int64)
        for j in range(self.n_bsdf):
            # the materials take their 2D pair from columns 1 and 2 (bsdfs/base.py); a sample's numbers have it in
            # 0 and 1, the lobe's choice in 2 (as the laboratory's MaterialSampling)
            uj = np.ascontiguousarray(u[j][:, [2, 0, 1]])
            pb, weight, live, origins, dirs = bsdf_rays(self.arrays, point, gnormal, error, frame, wo, material, owner,
                                                        uj)  # fmt: skip
            if live.size == 0:
                continue
            self.rays += live.size
            light, _, light_pdf, rgb = what_rays_see(
                self.arrays, self.lights, self.env, self.strategy_code, point, gnormal, compensated, live, origins,
                dirs, np.ascontiguousarray(weight[live]), self.tracer.intersect(origins, dirs),
            )  # fmt: skip
            for e in range(light.shape[1]):
                reached = np.flatnonzero(light[:, e] >= 0)
                if reached.size == 0:
                    continue
                at = live[reached]
                p_light = (
                    self.selector.pmf(ctx.subset(at), np.ascontiguousarray(light[reached, e])) * light_pdf[reached, e]
                )
                w = self._weight(self.n_bsdf, pb[at], self.n_light, p_light)
                out[at] += rgb[reached, e] * (w / self.n_bsdf)[:, None]  # each live row once per entry
        return out
