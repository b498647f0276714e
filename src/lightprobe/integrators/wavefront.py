"""Wavefront direct-illumination renderer: an environment map and area lights, BSDF/light/MIS sampling, shadow rays.

The image is rendered in *passes*: a pass is a few samples per pixel over a band of pixels (the whole image when
it fits the ``pass_samples`` budget), so memory is bounded by the pass, not by the sample count.  Its buffers list
the band's pixels in spread-out blocks (:mod:`lightprobe.integrators.schedule`), so that the threads' shares of
every kernel hold the same mix of sky and objects.  A pass runs as a wavefront of kernels:

1. camera rays (box filter with jitter) and their nearest hit: spheres and rectangles, then meshes through Embree
   (called from the kernel) for the rays that may reach one;
2. shading: for each hit, ``n_bsdf + K n_env`` directions from the chosen strategy, their unoccluded
   contributions, and shadow rays (tested against spheres and rectangles on the spot).  Scenes lit by an
   environment map alone shade in the five stages below (their measured fast path); scenes with area lights in
   the stages of :mod:`lightprobe.integrators.area_lights`;
3. Embree occlusion for the shadow rays that may reach a mesh (with the segment's end for area lights), in a
   kernel over the list of those rays;
4. accumulation: each pixel's samples are added *in sample order* to a running mean and variance (Welford).

Every random number is a hash of (seed, pixel, sample index, dimension) and each pixel is accumulated in sample
order, so the image is bit-identical for any pass size and any thread count.  Camera rays that miss show the
environment (black without one); camera rays that hit an emitter see its radiance.  Objects cast shadows but do
not light each other (direct illumination only).

Strategies (per camera sample, ``n = n_bsdf + K n_env`` directions for the single-technique ones, so that all
strategies cost the same number of shadow rays): ``uniform`` and ``cosine`` hemisphere sampling about the shading
normal, ``brdf``, ``env`` (light sampling: K lights picked by the light sampler, ``n_env`` samples each; the
environment is one of the lights), and ``mis`` with ``n_bsdf`` BSDF and K ``n_env`` light samples weighted by the
balance or power heuristic on sample-count-weighted densities.
"""

from __future__ import annotations

import math
import numbers
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numba
import numpy as np

from .._memory import fresh_array
from .._numba import jit_inline, jit_parallel, prange
from .._worksharing import claim_range, new_counter
from ..bsdfs.dispatch import bsdf_eval, bsdf_pdf
from ..bsdfs.lambert import LAMBERT
from ..bsdfs.phong import PHONG
from ..emitters.area import STRATEGIES as LIGHT_STRATEGIES
from ..emitters.envmap import (
    BILINEAR,
    env_coords,
    env_eval,
    env_lookup,
    env_pdf_at,
    env_sample_coords,
    env_sample_full,
)
from ..emitters.envmap_lanes import LANES, env_coords_block, env_sample_block, radiance_block
from ..emitters.envmap_lanes import applies as lanes_apply
from ..emitters.envmap_lanes import compiles as lanes_compile
from ..emitters.envmap_lanes import coords_apply as coords_in_lanes
from ..emitters.envmap_lanes import samples_apply as samples_in_lanes
from ..emitters.selection import SELECTORS, build_selector
from ..errors import ParameterError
from ..geometry.camera import camera_ray
from ..geometry.camera_lanes import nearest_block
from ..geometry.embree import FAR as MESH_FAR
from ..geometry.embree import (
    PACKET,
    closest_mesh_hit,
    mesh_occluded,
    occluded_packet,
    packet_ray,
    packet_words,
    packets_native,
)
from ..geometry.frame import to_local, to_world
from ..geometry.intersect import (
    MESH,
    MISS,
    blocked_by_mesh_core,
    closest_analytic,
    may_hit_mesh,
    occluded_analytic,
    ray_offset,
)
from ..geometry.raytracer import RayTracer
from ..geometry.scene import Scene
from ..geometry.shadow_lanes import shadow_block
from ..sampling.mis import mis_weight, mis_weight_over, mis_weight_share
from ..sampling.rng import SAMPLERS, SOBOL, sample_state, uniform, uniform_2d
from ..sampling.sobol_lanes import camera_numbers_block, slot_numbers_block
from . import adaptive
from .schedule import pass_pixels
from .techniques import (
    BLOCKED,
    BRDF,
    ENV,
    MIS,
    NONE,
    SLOT_BSDF,
    SLOT_ENV,
    SLOT_NONE,
    STRATEGIES,
    TEST_ANALYTIC,
    TEST_MESH,
    VISIBLE,
    load_shading_frame,
    sample_direction,
    store_shading_frame,
    technique_slot,
)

__all__ = [
    "STRATEGIES",
    "Accumulator",
    "RenderResult",
    "RenderSettings",
    "kernels_cached",
    "render",
    "result_from",
    "settings_for",
]

HEURISTICS = {"balance": 1.0, "power": 2.0}
DIFFUSE = "diffuse"  # mis_compensation's automatic choice: the compensated PDF on Lambertian materials only


# n_bsdf=None and n_env=None in scenes lit by an environment map alone (decisions.md 33, 34); else 1 each
_AUTO_BSDF_SAMPLES = 4
_AUTO_ENV_SAMPLES = 4


@dataclass(frozen=True)
class RenderSettings:
    """How to render.  ``spp`` camera samples per pixel; see the module docstring for the strategies."""

    spp: int = 16
    strategy: str = "mis"
    heuristic: str | None = None  # None: balance in scenes lit by an environment map alone, else power
    n_bsdf: int | None = None  # None: 4 in scenes lit by an environment map alone, else 1 (decisions 33, 34)
    n_env: int | None = None  # None: 4 in scenes lit by an environment map alone, else 1 (decisions 34)
    seed: int = 0
    first_sample: int = 0  # sample indices first_sample ... first_sample + spp - 1 (split and resumed renders)
    sampler: str = "sobol"
    env_candidates: int = 1  # > 1: resampled environment samples (RIS, Talbot et al. 2005) from this many candidates
    mis_compensation: bool | None = None  # None: on diffuse materials for MIS in scenes lit by an environment map alone
    light_sampler: str = "bvh"
    lights_per_sample: int = 1
    light_strategy: str = "solid-angle"
    time_limit: float | None = None
    threads: int | None = None
    pass_samples: int | None = None  # camera samples per pass; None: PASS_CAMERA_SAMPLES, at most PASS_SLOTS slots
    adaptive: bool = False  # ~spp / 4 in every pixel, then spp on average where the noise is (integrators/adaptive.py)

    def validate(self) -> None:
        """Raise :class:`ParameterError` naming the first setting of the wrong type or out of range."""
        for name in (
            "spp",
            "seed",
            "first_sample",
            "env_candidates",
            "lights_per_sample",
        ):
            _require(name, getattr(self, name), "integer")
        if self.pass_samples is not None:
            _require("pass_samples", self.pass_samples, "integer")
        for name in ("strategy", "sampler", "light_sampler", "light_strategy"):
            _require(name, getattr(self, name), "string")
        for name in ("n_bsdf", "n_env"):
            if getattr(self, name) is not None:
                _require(name, getattr(self, name), "integer")
        if self.heuristic is not None:
            _require("heuristic", self.heuristic, "string")
        if self.mis_compensation is not None:
            _require("mis_compensation", self.mis_compensation, "true or false")
        _require("adaptive", self.adaptive, "true or false")
        if self.time_limit is not None:
            _require("time_limit", self.time_limit, "number")
        if self.threads is not None:
            _require("threads", self.threads, "integer")
        if self.strategy not in STRATEGIES:
            raise ParameterError(f"strategy must be one of {list(STRATEGIES)}, got {self.strategy!r}")
        if self.heuristic is not None and self.heuristic not in HEURISTICS:
            raise ParameterError(f"heuristic must be one of {list(HEURISTICS)}, got {self.heuristic!r}")
        if self.spp < 1:
            raise ParameterError(f"spp must be an integer >= 1, got {self.spp!r}")
        # automatic counts: at least 1 each (render re-checks the counts it resolves them to)
        n_bsdf = 1 if self.n_bsdf is None else self.n_bsdf
        n_env = 1 if self.n_env is None else self.n_env
        if n_bsdf < 0 or n_env < 0 or n_bsdf + n_env < 1 or n_bsdf + n_env > 64:
            raise ParameterError(
                f"bsdf and env sample counts (n_bsdf, n_env) must be >= 0 with 1 to 64 in all, got {n_bsdf} and {n_env}"
            )
        if not 1 <= self.env_candidates <= 64:
            raise ParameterError(f"env_candidates must be from 1 to 64, got {self.env_candidates!r}")
        if self.sampler not in SAMPLERS:
            raise ParameterError(f"sampler must be one of {list(SAMPLERS)}, got {self.sampler!r}")
        if self.light_sampler not in SELECTORS:
            raise ParameterError(f"light_sampler must be one of {list(SELECTORS)}, got {self.light_sampler!r}")
        if self.light_strategy not in LIGHT_STRATEGIES:
            raise ParameterError(f"light_strategy must be one of {list(LIGHT_STRATEGIES)}, got {self.light_strategy!r}")
        if not 1 <= self.lights_per_sample <= 64 or self.shading_samples > 64:
            raise ParameterError(
                f"lights_per_sample must be >= 1 with at most 64 shading samples in all (n_bsdf + lights_per_sample "
                f"x n_env), got {self.lights_per_sample}"
            )
        if self.mis_compensation and self.strategy != "mis":
            raise ParameterError("mis_compensation needs strategy 'mis' (the compensated PDF is zero on dim texels)")
        if self.time_limit is not None and not (self.time_limit > 0 and math.isfinite(self.time_limit)):
            raise ParameterError(f"time_limit must be > 0 seconds, got {self.time_limit!r}")
        if self.threads is not None and not (1 <= self.threads <= 256):
            raise ParameterError(f"threads must be between 1 and 256, got {self.threads!r}")
        if not 0 <= self.seed < 2**63:
            raise ParameterError(f"seed must be in [0, 2^63), got {self.seed!r}")
        if self.first_sample < 0:
            raise ParameterError(f"first_sample must be >= 0, got {self.first_sample!r}")
        # a group's member j of sample k takes index k n + j (n <= 64 slots, sampling.rng.group_slot), in int64
        last = self.first_sample + self.spp * (adaptive.MAX_FACTOR if self.adaptive else 1)
        if last > _LAST_SAMPLE:
            what = "8 x spp (adaptive)" if self.adaptive else "first_sample + spp"
            raise ParameterError(f"{what} must be at most 2^56 (sample indices x 64 slots in 64 bits), got {last}")
        if self.pass_samples is not None and self.pass_samples < 1:
            raise ParameterError(f"pass_samples must be >= 1, got {self.pass_samples!r}")
        if self.adaptive:
            if (problem := adaptive.check_spp(self.spp)) is not None:
                raise ParameterError(problem)
            if self.first_sample != 0:
                raise ParameterError("adaptive sampling renders samples from 0 (first_sample must be 0)")

    @property
    def light_samples(self) -> int:
        """Light slots per camera sample: K lights, ``n_env`` samples each (the lecture's K N; an automatic ``n_env``
        counted as its smallest, 1, until :meth:`resolved` makes it concrete)."""
        return self.lights_per_sample * (1 if self.n_env is None else self.n_env)

    @property
    def shading_samples(self) -> int:
        """Shading slots per camera sample (``n_bsdf``'s automatic value counted as its smallest, 1, until
        :meth:`resolved` makes it concrete)."""
        return (1 if self.n_bsdf is None else self.n_bsdf) + self.light_samples

    def resolved(self, environment_only: bool) -> RenderSettings:
        """These settings with the automatic choices made, for a scene lit by an environment map alone or not.
        Measured on the peer and demo scenes and on eight of the seeds' sphere scenes (decisions.md 33, 34): where
        the environment is the only light, 4 BSDF + 4 environment samples per camera sample with the balance
        heuristic give the lowest error per second, or within 1.7x of it, everywhere (a camera sample's samples of
        one technique are one stratified set; they cost no extra camera ray); with 4000 area lights a second BSDF
        sample loses, so 1 + 1 and power.  The single-technique strategies take the same counts, so that every
        strategy traces n_bsdf + n_env directions per camera sample and equal samples mean equal rays."""
        n_bsdf = self.n_bsdf if self.n_bsdf is not None else (_AUTO_BSDF_SAMPLES if environment_only else 1)
        n_env = self.n_env if self.n_env is not None else (_AUTO_ENV_SAMPLES if environment_only else 1)
        heuristic = self.heuristic if self.heuristic is not None else ("balance" if environment_only else "power")
        return replace(self, n_bsdf=n_bsdf, n_env=n_env, heuristic=heuristic)


_LAST_SAMPLE = 2**56  # times 64 shading slots, still below 2^63
_clock = time.perf_counter  # the render's clock (time limits, seconds); tests replace it with one that ticks

_KINDS = {"integer": numbers.Integral, "number": numbers.Real, "string": str, "true or false": bool}


# The default pass: 2^19 camera samples, and at most 2^22 shading slots.  Larger passes win up to about 2^21 slots
# (launches and Python between kernels cost less per sample); since the stages got faster, 8 slots per camera sample
# in passes of 2^19 camera samples (4.2 M slots, 1.1 GB at the peak) render the peer scene 3 % faster than in 2^18
# (0.7 GB): fewer launches, each of which starts on tables and accumulators the stage before evicted from the caches
# (decisions.md 28, 40, 51).
PASS_CAMERA_SAMPLES = 1 << 19
PASS_SLOTS = 1 << 22


def default_pass_samples(shading_samples: int) -> int:
    """Camera samples per pass when ``pass_samples`` is not given, for ``shading_samples`` slots each."""
    return max(1, min(PASS_CAMERA_SAMPLES, PASS_SLOTS // max(1, shading_samples)))


def _require(name: str, value, kind: str) -> None:
    """``value`` is an "integer", "number", "string" or "true or false" (a bool is not a number here)."""
    ok = isinstance(value, _KINDS[kind]) and not (kind in ("integer", "number") and isinstance(value, bool))
    if not ok:
        article = "" if kind == "true or false" else "an " if kind == "integer" else "a "
        raise ParameterError(f"{name} must be {article}{kind}, got {value!r}")


@dataclass
class RenderResult:
    """Mean radiance (H, W, 3), variance of that mean (H, W, 3), samples per pixel (H, W), and statistics."""

    image: np.ndarray
    variance: np.ndarray
    counts: np.ndarray
    stats: dict = field(default_factory=dict)
    #: the running float64 sums (mean, M2, counts) that produced the image: resume or merge from them
    accumulator: Accumulator | None = None


# --- kernels ------------------------------------------------------------------------------------------------------
@jit_inline
def _camera_ray_into(cam, sampler, seed, pixels, spp_pass, sample_start, dirs, k):
    """Camera sample k's ray direction, into dirs[k] (box filter with jitter)."""
    pixel = pixels[k // spp_pass]
    rs = sample_state(sampler, seed, pixel, sample_start + k % spp_pass)
    u0, u1 = uniform_2d(rs, 0)
    dirs[k, 0], dirs[k, 1], dirs[k, 2] = camera_ray(cam, pixel, u0, u1)


@jit_inline
def _mesh_hit_into(s, cam, mesh_scene, scratch, ray_counts, dirs, t, kind, index, prim, b1, b2, k):
    """Camera sample k's nearest mesh hit through Embree, where its ray may reach a mesh's bounds before its
    analytic hit t[k]; the mesh hit replaces that one when nearer."""
    prim[k] = 0
    b1[k] = 0.0
    b2[k] = 0.0
    ox, oy, oz = cam[0], cam[1], cam[2]
    dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
    if mesh_scene != 0 and may_hit_mesh(s, ox, oy, oz, dx, dy, dz, t[k]):
        ray_counts[numba.get_thread_id(), 0] += 1
        far = t[k] if t[k] < np.inf else MESH_FAR
        mt, mesh, face, mb1, mb2 = closest_mesh_hit(mesh_scene, scratch, ox, oy, oz, dx, dy, dz, far)
        if mesh >= 0:
            t[k], kind[k], index[k], prim[k], b1[k], b2[k] = mt, MESH, mesh, face, mb1, mb2


# The analytic nearest hits run 8 camera samples at a time in vector IR (geometry/camera_lanes.py): one ray at a time
# they were half of this stage (decisions.md 49, 50).  Meshes in the same loop: camera rays are coherent, and here
# they cost 0.27 s of the peer scene's 64-spp render against 0.42 s in a loop of their own (the opposite of shadow
# rays, decisions.md 30).
@jit_parallel
def _camera_pass(
    s,
    cam,
    sampler,
    seed,
    pixels,
    spp_pass,
    sample_start,
    mesh_scene,
    scratch,
    ray_counts,
    dirs,
    t,
    kind,
    index,
    prim,
    b1,
    b2,
    counter,
    workers,
):
    """Camera rays and their nearest hits: analytic shapes, 8 rays at a time (one at a time through the shapes'
    hierarchy when the scene has one), then meshes through Embree where a ray may reach a mesh's bounds before its
    analytic hit."""
    n = dirs.shape[0]
    n_work = (n + LANES - 1) // LANES
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for block in range(lo, hi):
                start = block * LANES
                stop = min(start + LANES, n)
                if sampler == SOBOL:
                    # the rays' positions in their pixels 8 at a time (sampling/sobol_lanes.py), into dirs until the
                    # directions replace them: the same bits as uniform_2d
                    camera_numbers_block(dirs, seed, pixels, spp_pass, sample_start, start)
                    for k in range(start, stop):
                        dirs[k, 0], dirs[k, 1], dirs[k, 2] = camera_ray(
                            cam, pixels[k // spp_pass], dirs[k, 0], dirs[k, 1]
                        )
                else:
                    for k in range(start, stop):
                        _camera_ray_into(cam, sampler, seed, pixels, spp_pass, sample_start, dirs, k)
                if s.tree_skip.shape[0] == 0:
                    nearest_block(dirs, t, kind, index, cam, s.spheres, s.rects, start)
                else:  # many shapes: each ray walks their hierarchy (geometry/shape_bvh.py)
                    for k in range(start, stop):
                        t[k], kind[k], index[k] = closest_analytic(
                            s, cam[0], cam[1], cam[2], dirs[k, 0], dirs[k, 1], dirs[k, 2], np.inf
                        )
                for k in range(start, stop):
                    _mesh_hit_into(s, cam, mesh_scene, scratch, ray_counts, dirs, t, kind, index, prim, b1, b2, k)
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _camera_scalar_pass(
    s,
    cam,
    sampler,
    seed,
    pixels,
    spp_pass,
    sample_start,
    mesh_scene,
    scratch,
    ray_counts,
    dirs,
    t,
    kind,
    index,
    prim,
    b1,
    b2,
    counter,
    workers,
):
    """:func:`_camera_pass` one ray at a time: where the vector intrinsics do not compile."""
    ox, oy, oz = cam[0], cam[1], cam[2]
    n_work = dirs.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for k in range(lo, hi):
                _camera_ray_into(cam, sampler, seed, pixels, spp_pass, sample_start, dirs, k)
                t[k], kind[k], index[k] = closest_analytic(s, ox, oy, oz, dirs[k, 0], dirs[k, 1], dirs[k, 2], np.inf)
                _mesh_hit_into(s, cam, mesh_scene, scratch, ray_counts, dirs, t, kind, index, prim, b1, b2, k)
            lo, hi = claim_range(counter, n_work)


# Shading runs as five kernels rather than one: the environment lookups are cache misses (the map and its CDFs
# are megabytes), and in small loops of independent iterations the CPU overlaps many misses, while in one large
# loop body it stalls on each (measured: a bilinear lookup costs 35 ns in its own loop, 150 ns inside the body).
# Nor do they run per batch of camera samples through every stage: each stage's tables stay hot for a whole pass
# (decisions.md 41).
# Slot r = k * m + j is shading sample j of camera sample k; its state says which technique made it.


@jit_parallel
def _shade_setup(
    s,
    env,
    cam,
    sampler,
    seed,
    pixels,
    spp_pass,
    sample_start,
    dirs,
    t,
    kind,
    index,
    prim,
    b1,
    b2,
    strategy,
    n_bsdf,
    n_env,
    direct,
    point,
    gnormal,
    point_error,
    frame,
    wo_local,
    material,
    state,
    wdir,
    wloc,
    tpdf,
    bweight,
    env_u,
    numbers,
    counter,
    workers,
):
    """Hit points, shading frames, and every direction except the environment samples (only their numbers).
    ``numbers``: one (m, 3) row per thread for a camera sample's Sobol' numbers, so that they do not go through the
    pass buffers (decisions.md 56)."""
    m = n_bsdf + n_env
    ox, oy, oz = cam[0], cam[1], cam[2]
    n_work = dirs.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for k in range(lo, hi):
                base = k * m
                material[k] = -1  # no shading for this camera sample (a miss, or the back of a one-sided surface)
                for j in range(m):
                    state[base + j] = SLOT_NONE
                dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
                if kind[k] == MISS:
                    direct[k, 0], direct[k, 1], direct[k, 2] = env_eval(env, dx, dy, dz)
                    continue
                direct[k, 0] = direct[k, 1] = direct[k, 2] = 0.0
                hit = (kind[k], index[k], prim[k], b1[k], b2[k], t[k])
                _, _, _, wo = store_shading_frame(
                    s, k, hit, ox, oy, oz, dx, dy, dz, point, gnormal, point_error, frame, wo_local, material
                )
                if wo[2] <= 0.0:
                    continue
                ts, tt, ns, wo = load_shading_frame(frame, wo_local, k)
                mk, mp = s.material_kind[material[k]], s.material_params[material[k]]
                rs = sample_state(sampler, seed, pixels[k // spp_pass], sample_start + k % spp_pass)
                sobol = sampler == SOBOL
                own = numbers[numba.get_thread_id()]
                if sobol:
                    # the slots' Sobol' numbers 8 at a time (sampling/sobol_lanes.py): the same bits as uniform_2d and
                    # uniform below
                    for first in range(0, m, LANES):
                        slot_numbers_block(own, rs[2], rs[3], strategy == MIS, n_bsdf, m, first, first)
                for j in range(m):
                    r = base + j
                    technique = strategy
                    if strategy == MIS:
                        technique = BRDF if j < n_bsdf else ENV
                    if sobol:
                        u0, u1, u2 = own[j, 0], own[j, 1], own[j, 2]
                    else:
                        rj, slot = technique_slot(rs, strategy, n_bsdf, n_env, j)
                        u0, u1 = uniform_2d(rj, 2 + 3 * slot)
                        u2 = -1.0  # drawn below where a technique takes it
                    if technique == ENV:
                        env_u[r, 0] = u0
                        env_u[r, 1] = u1
                        state[r] = SLOT_ENV
                        continue
                    if not sobol:
                        u2 = uniform(rj, 4 + 3 * slot)
                    st, wi, pdf, w = sample_direction(technique, mk, mp, wo, u0, u1, u2)
                    if st == SLOT_NONE:
                        continue
                    if st == SLOT_BSDF:
                        bweight[r, 0], bweight[r, 1], bweight[r, 2] = w
                    state[r] = st
                    wx, wy, wz = to_world(ts, tt, ns, wi[0], wi[1], wi[2])
                    wdir[r, 0], wdir[r, 1], wdir[r, 2] = wx, wy, wz
                    if st != SLOT_BSDF:  # the finish stage weighs a BSDF sample by bweight, the others by wi
                        wloc[r, 0], wloc[r, 1], wloc[r, 2] = wi
                    tpdf[r] = pdf
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _env_sample_stage(env, compensate, m, material, frame, state, env_u, wdir, tpdf, uv, counter, workers):
    """Environment samples: directions, densities and lat-long coordinates; those below the surface are dropped."""
    n_work = state.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for r in range(lo, hi):
                if state[r] != SLOT_ENV:
                    continue
                k = r // m
                wx, wy, wz, pdf, u, y, cos_theta = env_sample_full(
                    env, compensate[material[k]], env_u[r, 0], env_u[r, 1]
                )
                if frame[k, 6] * wx + frame[k, 7] * wy + frame[k, 8] * wz <= 0.0 or pdf <= 0.0:
                    state[r] = SLOT_NONE
                    continue
                wdir[r, 0], wdir[r, 1], wdir[r, 2] = wx, wy, wz
                tpdf[r] = pdf
                uv[r, 0] = u
                uv[r, 1] = env_sample_coords(env, y, cos_theta)
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _env_sample_lanes_stage(
    env, compensate, strategy, n_bsdf, m, material, frame, state, env_u, wdir, tpdf, uv, counter, workers
):
    """:func:`_env_sample_stage` 8 environment slots at a time (emitters/envmap_lanes.py), for the bilinear
    density: under MIS a camera sample's environment slots are its last m - n_bsdf, under ``env`` all m, and the
    other strategies have none (the lanes compute every slot they are given, so they are given none)."""
    first = n_bsdf if strategy == MIS else 0
    count = m - first if strategy == MIS or strategy == ENV else 0
    n_work = (material.shape[0] * count + LANES - 1) // LANES
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for block in range(lo, hi):
                env_sample_block(
                    env_u,
                    state,
                    material,
                    compensate,
                    m,
                    frame,
                    env.luminance,
                    env.node_sines,
                    env.conditional_cdf,
                    env.marginal_cdf,
                    env.comp_conditional_cdf,
                    env.comp_marginal_cdf,
                    env.row_guide,
                    env.marginal_guide,
                    env.comp_row_guide,
                    env.comp_marginal_guide,
                    env.comp_offset,
                    env.row_angles,
                    env.column_angles,
                    env.to_world,
                    wdir,
                    tpdf,
                    uv,
                    first,
                    count,
                    block * LANES,
                )
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _env_resample_stage(
    s,
    env,
    compensate,
    m,
    strategy,
    n_bsdf,
    n_env,
    env_candidates,
    sampler,
    seed,
    pixels,
    spp_pass,
    sample_start,
    frame,
    wo_local,
    material,
    state,
    env_u,
    wdir,
    tpdf,
    uv,
    epdf,
    counter,
    workers,
):
    """Environment samples by resampled importance sampling (Talbot, Cline and Egbert 2005): M candidates x_i from
    the environment's PDF p, one kept with probability proportional to w_i = p^(x_i) / p(x_i), where the target
    p^ = luminance(f L) cos is the product the light sample estimates (map x BSDF x cosine, without visibility).
    The kept y is weighted by W = (1/M) sum w_i / p^(y), unbiased wherever p^ > 0 covers f L cos (it does: the
    luminance weights are positive).  ``tpdf`` gets the effective density 1 / W, ``epdf`` the source density p(y)
    for the MIS weights: weights from p and the BSDF's pdf still sum to one at every direction, which is all MIS
    needs to stay unbiased (Veach 1997, 9.2).  Candidate i > 0 of slot j takes the random numbers of virtual slot
    64 + j M + i (past every real slot); the choice uses each candidate's third number (weighted reservoir
    sampling), so the kept sample is a pure function of the sample's coordinates."""
    n_work = state.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for r in range(lo, hi):
                if state[r] != SLOT_ENV:
                    continue
                k = r // m
                j = r % m
                rs = sample_state(sampler, seed, pixels[k // spp_pass], sample_start + k % spp_pass)
                ts, tt, ns, wo = load_shading_frame(frame, wo_local, k)
                mk, mp = s.material_kind[material[k]], s.material_params[material[k]]
                wsum = 0.0
                kept_target = 0.0
                kept = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # direction, source pdf, u, v
                for i in range(env_candidates):
                    if i == 0:
                        rj, slot = technique_slot(rs, strategy, n_bsdf, n_env, j)
                        u0, u1, uc = env_u[r, 0], env_u[r, 1], uniform(rj, 4 + 3 * slot)
                    else:
                        v = 64 + j * env_candidates + i
                        (u0, u1), uc = uniform_2d(rs, 2 + 3 * v), uniform(rs, 4 + 3 * v)
                    wx, wy, wz, pdf, u, y, cos_theta = env_sample_full(env, compensate[material[k]], u0, u1)
                    if pdf <= 0.0:
                        continue
                    wi = to_local(ts, tt, ns, wx, wy, wz)
                    if wi[2] <= 0.0:
                        continue
                    f = bsdf_eval(mk, mp, wo, wi)
                    vv = env_sample_coords(env, y, cos_theta)
                    lr, lg, lb = env_lookup(env, u, vv)
                    target = (0.212671 * f[0] * lr + 0.715160 * f[1] * lg + 0.072169 * f[2] * lb) * wi[2]
                    if not target > 0.0:
                        continue
                    w = target / pdf
                    wsum += w
                    if uc * wsum < w:  # keep candidate i with probability w_i / (w_0 + ... + w_i)
                        kept_target = target
                        kept = (wx, wy, wz, pdf, u, vv)
                if wsum <= 0.0 or not math.isfinite(wsum):
                    state[r] = SLOT_NONE
                    continue
                wdir[r, 0], wdir[r, 1], wdir[r, 2] = kept[0], kept[1], kept[2]
                tpdf[r] = kept_target * env_candidates / wsum
                epdf[r] = kept[3]
                uv[r, 0] = kept[4]
                uv[r, 1] = kept[5]
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _env_coords_stage(env, compensate, m, material, mis, state, wdir, uv, epdf, counter, workers):
    """Lat-long coordinates of every live slot's direction (environment samples have theirs already), and the
    environment's density for BSDF samples under MIS."""
    n_work = state.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for r in range(lo, hi):
                st = state[r]
                if st == SLOT_NONE or st == SLOT_ENV:
                    continue
                u, v, cos_theta = env_coords(env, wdir[r, 0], wdir[r, 1], wdir[r, 2])
                uv[r, 0] = u
                uv[r, 1] = v
                if mis and st == SLOT_BSDF:
                    epdf[r] = env_pdf_at(env, compensate[material[r // m]], u, v, cos_theta)
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _env_coords_lanes_stage(
    env, compensate, strategy, n_bsdf, m, material, mis, state, wdir, uv, epdf, counter, workers
):
    """:func:`_env_coords_stage` 8 slots at a time (emitters/envmap_lanes.py), for the bilinear density: the slots
    that are not environment samples -- under MIS a camera sample's first n_bsdf, under ``env`` none, else all m --
    numbered over the pass's camera samples, so that the lanes hold no environment samples (decisions.md 46)."""
    count = n_bsdf if strategy == MIS else (0 if strategy == ENV else m)
    n_work = (material.shape[0] * count + LANES - 1) // LANES
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for block in range(lo, hi):
                env_coords_block(
                    state,
                    material,
                    compensate,
                    m,
                    mis,
                    wdir,
                    env.to_env,
                    env.luminance,
                    env.node_sines,
                    env.marginal_cdf,
                    env.comp_marginal_cdf,
                    env.comp_offset,
                    uv,
                    epdf,
                    0,
                    count,
                    block * LANES,
                )
            lo, hi = claim_range(counter, n_work)


# The radiance lookups run 8 slots at a time in vector IR (emitters/envmap_lanes.py): half the time of the scalar
# lookup (decisions.md 42).  Every slot of a pass takes this path, so block boundaries never change a pixel.
@jit_parallel
def _env_radiance_stage(env, state, uv, radiance, counter, workers):
    """Radiance for every live slot, 8 slots at a time."""
    n_work = (state.shape[0] + LANES - 1) // LANES
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for block in range(lo, hi):
                radiance_block(radiance, env.image, uv, state, block * LANES)
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _env_radiance_scalar_stage(env, state, uv, radiance, counter, workers):
    """Radiance for every live slot, one at a time: for the maps :func:`radiance_block` does not take (nearest
    lookups, one-row maps)."""
    n_work = state.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for r in range(lo, hi):
                if state[r] != SLOT_NONE:
                    radiance[r, 0], radiance[r, 1], radiance[r, 2] = env_lookup(env, uv[r, 0], uv[r, 1])
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _shade_finish(
    s,
    strategy,
    env_candidates,
    n_bsdf,
    n_env,
    beta,
    point,
    gnormal,
    frame,
    wo_local,
    material,
    state,
    wdir,
    wloc,
    tpdf,
    bweight,
    radiance,
    epdf,
    contrib,
    flags,
    counter,
    workers,
):
    """Contributions (BSDF value, cosine, MIS weight); each nonzero one's shadow ray is flagged TEST_ANALYTIC for
    :func:`_analytic_shadow_stage`."""
    m = n_bsdf + n_env
    inv_m = 1.0 / m
    n_work = point.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for k in range(lo, hi):
                base = k * m
                for j in range(m):
                    flags[base + j] = NONE
                if material[k] < 0:
                    continue
                ts, tt, ns, wo = load_shading_frame(frame, wo_local, k)
                mk, mp = s.material_kind[material[k]], s.material_params[material[k]]
                for j in range(m):
                    r = base + j
                    st = state[r]
                    if st == SLOT_NONE:
                        continue
                    wx, wy, wz = wdir[r, 0], wdir[r, 1], wdir[r, 2]
                    lr, lg, lb = radiance[r, 0], radiance[r, 1], radiance[r, 2]
                    if st == SLOT_BSDF:
                        scale = inv_m
                        if strategy == MIS:
                            scale = mis_weight_share(n_bsdf, tpdf[r], n_env, epdf[r], beta)
                        cr, cg, cb = bweight[r, 0] * lr * scale, bweight[r, 1] * lg * scale, bweight[r, 2] * lb * scale
                    else:
                        if st == SLOT_ENV:
                            wi = to_local(ts, tt, ns, wx, wy, wz)
                        else:
                            wi = (wloc[r, 0], wloc[r, 1], wloc[r, 2])
                        f = bsdf_eval(mk, mp, wo, wi)
                        if f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0:
                            continue
                        pdf = tpdf[r]
                        if strategy != MIS:
                            scale = wi[2] / pdf * inv_m
                        else:
                            pb = bsdf_pdf(mk, mp, wo, wi)
                            # a resampled sample's weight uses the density it was drawn from, not its effective one
                            if st == SLOT_ENV and env_candidates > 1:
                                p_light = epdf[r]
                                scale = wi[2] / pdf * mis_weight(n_env, p_light, n_bsdf, pb, beta) / n_env
                            else:
                                scale = wi[2] * mis_weight_over(n_env, pdf, n_bsdf, pb, beta)
                        cr, cg, cb = f[0] * lr * scale, f[1] * lg * scale, f[2] * lb * scale
                    if cr == 0.0 and cg == 0.0 and cb == 0.0:
                        continue
                    contrib[r, 0], contrib[r, 1], contrib[r, 2] = cr, cg, cb
                    flags[r] = TEST_ANALYTIC
            lo, hi = claim_range(counter, n_work)


@jit_inline
def _shadow_ray(m, point, gnormal, point_error, wdir, r):
    """Slot r's shadow ray: its direction, from its camera sample's hit point offset along the geometric normal by
    the point's error bound (intersect.ray_offset).  Returns (origin x, y, z, direction x, y, z)."""
    k = r // m
    wx, wy, wz = wdir[r, 0], wdir[r, 1], wdir[r, 2]
    qx, qy, qz = ray_offset(
        point[k, 0], point[k, 1], point[k, 2], gnormal[k, 0], gnormal[k, 1], gnormal[k, 2], point_error[k], wx, wy, wz
    )
    return qx, qy, qz, wx, wy, wz


# The analytic shapes' shadow tests run 8 slots at a time in vector IR (geometry/shadow_lanes.py): inside the finish
# stage, one ray at a time with early exits, they were half of its time (decisions.md 49).
@jit_parallel
def _analytic_shadow_stage(s, m, point, gnormal, point_error, wdir, flags, counter, workers):
    """Shadow rays of the slots flagged TEST_ANALYTIC against the spheres and rectangles (BLOCKED), then the
    meshes' bounding boxes (TEST_MESH, for :func:`_mesh_shadow_stage`, or VISIBLE), 8 slots at a time."""
    if s.tree_skip.shape[0] > 0:  # many shapes: each ray walks their hierarchy, as the scalar stage does
        _analytic_shadow_slots(s, m, point, gnormal, point_error, wdir, flags, counter, workers)
        return
    n_work = (flags.shape[0] + LANES - 1) // LANES
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for block in range(lo, hi):
                shadow_block(
                    flags,
                    point,
                    gnormal,
                    point_error,
                    wdir,
                    s.spheres,
                    s.rects,
                    s.mesh_bounds,
                    s.mesh_spheres,
                    m,
                    block * LANES,
                )
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _analytic_shadow_scalar_stage(s, m, point, gnormal, point_error, wdir, flags, counter, workers):
    """:func:`_analytic_shadow_stage` one slot at a time: where the vector intrinsics do not compile."""
    _analytic_shadow_slots(s, m, point, gnormal, point_error, wdir, flags, counter, workers)


@jit_inline
def _analytic_shadow_slots(s, m, point, gnormal, point_error, wdir, flags, counter, workers):
    """The analytic shadow tests one slot at a time (the scalar stage's body, and the lanes stage's with a shape
    hierarchy)."""
    n_work = flags.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for r in range(lo, hi):
                if flags[r] != TEST_ANALYTIC:
                    continue
                qx, qy, qz, wx, wy, wz = _shadow_ray(m, point, gnormal, point_error, wdir, r)
                if occluded_analytic(s, qx, qy, qz, wx, wy, wz, np.inf) or blocked_by_mesh_core(
                    s, qx, qy, qz, wx, wy, wz
                ):
                    flags[r] = BLOCKED
                else:
                    flags[r] = TEST_MESH if may_hit_mesh(s, qx, qy, qz, wx, wy, wz, np.inf) else VISIBLE
            lo, hi = claim_range(counter, n_work)


# Shadow rays that may reach a mesh are traced in a loop of their own, not inside _shade_finish: on the peer scene at
# 64 spp, 3.9 M such rays added about 1.1 s to that loop body and take 0.9 s here, where the shading work does not
# evict Embree's BVH between rays (decisions.md 30).  Each claimed chunk of slots gathers its flagged ones as it scans
# them: a work list gathered in NumPy before the stage (np.flatnonzero, one thread) cost 4-5 ms a pass
# (decisions.md 60).  Which rays share a packet changes no answer.
@jit_parallel
def _mesh_shadow_stage(m, mesh_scene, scratch, ray_counts, point, gnormal, point_error, wdir, flags, counter, workers):
    """Shadow rays flagged TEST_MESH through Embree 8 at a time (decisions.md 55): each becomes VISIBLE or
    BLOCKED."""
    n_work = flags.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        packet = packet_words(scratch)
        floats = packet.view(np.float32)
        lanes = np.empty(PACKET, np.int64)  # the slots in the packet
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            count = 0
            for r in range(lo, hi + 1):
                if r < hi:
                    if flags[r] != TEST_MESH:
                        continue
                    qx, qy, qz, wx, wy, wz = _shadow_ray(m, point, gnormal, point_error, wdir, r)
                    packet_ray(packet, floats, count, qx, qy, qz, wx, wy, wz, MESH_FAR)
                    lanes[count] = r
                    count += 1
                if count == PACKET or (r == hi and count > 0):  # a full packet, or the chunk's last rays
                    blocked = occluded_packet(mesh_scene, packet, floats, count)
                    ray_counts[numba.get_thread_id(), 1] += count
                    for i in range(count):
                        flags[lanes[i]] = BLOCKED if blocked >> i & 1 else VISIBLE
                    count = 0
            lo, hi = claim_range(counter, n_work)


@jit_parallel
def _mesh_shadow_single_stage(
    m, mesh_scene, scratch, ray_counts, point, gnormal, point_error, wdir, flags, counter, workers
):
    """:func:`_mesh_shadow_stage` one ray at a time: where Embree's 8-ray packets are not native."""
    n_work = flags.shape[0]
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for r in range(lo, hi):
                if flags[r] != TEST_MESH:
                    continue
                qx, qy, qz, wx, wy, wz = _shadow_ray(m, point, gnormal, point_error, wdir, r)
                ray_counts[numba.get_thread_id(), 1] += 1
                flags[r] = BLOCKED if mesh_occluded(mesh_scene, scratch, qx, qy, qz, wx, wy, wz, MESH_FAR) else VISIBLE
            lo, hi = claim_range(counter, n_work)


#: the Embree stages that trace a work list gathered from the pass buffers before they run (the area-light path's,
#: area_lights.WORKLISTS); this path's stages scan the slots themselves
WORKLISTS: dict = {}


@jit_parallel
def _accumulate(
    direct, contrib, flags, m, spp_pass, pixels, acc_mean, acc_m2, acc_count, acc_nonfinite, counter, workers
):
    mean, m2, count, nonfinite = acc_mean, acc_m2, acc_count, acc_nonfinite
    n_pixels = direct.shape[0] // spp_pass
    n_work = n_pixels
    for worker in prange(workers):  # noqa: B007 - one per thread, claiming chunks (_worksharing)
        lo, hi = claim_range(counter, n_work)
        while lo < hi:
            for q in range(lo, hi):
                p = pixels[q]
                for j in range(spp_pass):
                    k = q * spp_pass + j
                    vr, vg, vb = direct[k, 0], direct[k, 1], direct[k, 2]
                    for i in range(k * m, k * m + m):
                        if flags[i] == VISIBLE:
                            vr += contrib[i, 0]
                            vg += contrib[i, 1]
                            vb += contrib[i, 2]
                    if not (math.isfinite(vr) and math.isfinite(vg) and math.isfinite(vb)):
                        vr = vg = vb = 0.0
                        nonfinite[p] += 1
                    count[p] += 1
                    c = count[p]
                    d0 = vr - mean[p, 0]
                    d1 = vg - mean[p, 1]
                    d2 = vb - mean[p, 2]
                    mean[p, 0] += d0 / c
                    mean[p, 1] += d1 / c
                    mean[p, 2] += d2 / c
                    m2[p, 0] += d0 * (vr - mean[p, 0])
                    m2[p, 1] += d1 * (vg - mean[p, 1])
                    m2[p, 2] += d2 * (vb - mean[p, 2])
            lo, hi = claim_range(counter, n_work)


# --- driver -------------------------------------------------------------------------------------------------------
class Accumulator:
    """Per-pixel running statistics in float64: mean, M2 (sum of squared deviations, Welford), sample and
    non-finite counts.  A render continues one (``render(..., resume=acc)``, bit for bit the same as not
    stopping); :meth:`merged` combines two over disjoint sample ranges."""

    def __init__(self, n_pixels: int):
        self.mean = np.zeros((n_pixels, 3))
        self.m2 = np.zeros((n_pixels, 3))
        self.count = np.zeros(n_pixels, dtype=np.int64)
        self.nonfinite = np.zeros(n_pixels, dtype=np.int64)

    def copy(self) -> Accumulator:
        other = Accumulator(0)
        other.mean, other.m2 = self.mean.copy(), self.m2.copy()
        other.count, other.nonfinite = self.count.copy(), self.nonfinite.copy()
        return other

    def merged(self, other: Accumulator) -> Accumulator:
        """Both sample sets as one: Chan, Golub and LeVeque's pairwise update (1979), mean_ab = mean_a + delta
        n_b / n and M2_ab = M2_a + M2_b + delta^2 n_a n_b / n.  Equal to a single run up to float64 rounding."""
        if self.mean.shape != other.mean.shape:
            raise ParameterError(f"cannot merge renders of {self.count.size} and {other.count.size} pixels")
        out = Accumulator(0)
        na, nb = self.count[:, None].astype(float), other.count[:, None].astype(float)
        n = na + nb
        delta = other.mean - self.mean
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(n > 0, nb / n, 0.0)
            out.mean = self.mean + delta * share
            out.m2 = self.m2 + other.m2 + np.where(n > 0, delta**2 * na * nb / n, 0.0)
        out.count = self.count + other.count
        out.nonfinite = self.nonfinite + other.nonfinite
        return out

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean, "m2": self.m2, "count": self.count, "nonfinite": self.nonfinite}

    @classmethod
    def from_arrays(cls, arrays) -> Accumulator:
        acc = cls(0)
        acc.mean = np.array(arrays["mean"], np.float64)
        acc.m2 = np.array(arrays["m2"], np.float64)
        acc.count = np.array(arrays["count"], np.int64)
        acc.nonfinite = np.array(arrays["nonfinite"], np.int64)
        return acc


def _placeholder_environment():
    """An environment for kernels that must be given one when the scene has none (it is never looked up)."""
    from ..emitters.envmap import EnvironmentMap
    from ..emitters.procedural import constant

    return EnvironmentMap.from_array(constant(1.0, width=2, height=1), source="none")


def _takes_area_path(scene: Scene, settings: RenderSettings) -> bool:
    return bool(scene.emitters or scene.lights) or scene.environment is None or settings.lights_per_sample > 1


def settings_for(scene: Scene, settings: RenderSettings) -> RenderSettings:
    """``settings`` with the automatic choices made as :func:`render` makes them for ``scene``."""
    return settings.resolved(environment_only=not _takes_area_path(scene, settings))


def _check_material_strategy(scene: Scene, settings: RenderSettings) -> None:
    if settings.strategy == "mis":
        for name, bsdf in scene.materials.items():
            if bsdf.kind == PHONG and getattr(bsdf, "estimator", "mixture") != "mixture":
                raise ParameterError(f"material {name!r}: MIS needs Phong's mixture estimator (seed eq. 19)")


def _pass_buffers(n: int, m: int, environment_stages: bool = True) -> dict[str, np.ndarray]:
    """Arrays of one pass: ``n`` camera samples, ``m`` shading slots each, keyed by kernel parameter name; without
    the environment stages' own three when the render takes the area-light path.  (Mapped without huge pages, and
    populated when mapped: first touches in the first passes took up to twice a pass's time, decisions.md 32, 39.)"""
    nm = n * m
    buffers = {
        # camera samples
        "dirs": fresh_array((n, 3)),  # camera ray directions
        "t": fresh_array(n),  # hit distance (inf: miss)
        "kind": fresh_array(n, np.int64),  # MISS / MESH / SPHERE / RECT
        "index": fresh_array(n, np.int64),  # which mesh, sphere or rectangle
        "prim": fresh_array(n, np.int64),  # mesh face
        "b1": fresh_array(n),  # barycentrics of a mesh hit
        "b2": fresh_array(n),
        "direct": fresh_array((n, 3)),  # radiance seen directly (the environment, for misses)
        "point": fresh_array((n, 3)),  # hit point
        "gnormal": fresh_array((n, 3)),  # geometric normal
        "point_error": fresh_array(n),  # the hit point's error bound along it (intersect.ray_offset)
        "frame": fresh_array((n, 9)),  # shading frame s, t, n
        "wo_local": fresh_array((n, 3)),  # direction to the viewer, local
        "material": fresh_array(n, np.int64),  # -1: nothing to shade
        # shading slots, r = k m + j
        "state": fresh_array(nm, np.int8),  # SLOT_*: which technique made the direction
        "wdir": fresh_array((nm, 3)),  # direction, world
        "wloc": fresh_array((nm, 3)),  # direction, local
        "tpdf": fresh_array(nm),  # density of the technique that made it
        "bweight": fresh_array((nm, 3)),  # BSDF sample weight
        "radiance": fresh_array((nm, 3)),  # environment radiance along the direction
        "contrib": fresh_array((nm, 3)),  # unoccluded contribution
        "flags": fresh_array(nm, np.int8),  # NONE / VISIBLE / TEST_MESH / BLOCKED
    }
    if environment_stages:
        buffers["env_u"] = fresh_array((nm, 2))  # random numbers of environment samples
        buffers["uv"] = fresh_array((nm, 2))  # lat-long coordinates of environment samples
        buffers["epdf"] = fresh_array(nm)  # environment density of BSDF samples (MIS)
    return buffers


#: when a dict, every kernel launch adds its seconds under the kernel's name (``benchmarks/peer_scene.py --profile``)
PROFILE: dict | None = None


def _compensated_materials(kinds: np.ndarray, compensated) -> np.ndarray:
    """Per material, whether its environment samples (and the MIS weights of its BSDF samples) use the compensated
    PDF: every material for True, none for False, Lambertian ones for ``DIFFUSE``.  Both techniques at a shading
    point see the same density, so each point's MIS weights still sum to one (Veach 1997, 9.2)."""
    if compensated == DIFFUSE:
        return np.ascontiguousarray(kinds == LAMBERT)
    return np.full(kinds.shape[0], bool(compensated))


def _launch(kernel, values: dict) -> None:
    """Call a kernel with its arguments taken by parameter name from ``values``."""
    code = kernel.py_func.__code__
    if "counter" in code.co_varnames[: code.co_argcount]:
        values["counter"][0] = 0  # the chunks of _worksharing.claim start over
        values["workers"] = numba.get_num_threads()  # one per thread (in a kernel the call would prevent caching)
    args = [values[name] for name in code.co_varnames[: code.co_argcount]]
    if PROFILE is None:
        kernel(*args)
        return
    start = time.perf_counter()
    kernel(*args)
    name = kernel.py_func.__name__.lstrip("_")
    PROFILE[name] = PROFILE.get(name, 0.0) + time.perf_counter() - start


def render(
    scene: Scene,
    settings: RenderSettings | None = None,
    *,
    progress: Callable[[dict], None] | None = None,
    tracer: RayTracer | None = None,
    resume: Accumulator | None = None,
) -> RenderResult:
    """Render ``scene``; ``progress(stats)`` is called after every pass.  Ctrl-C keeps what has been accumulated
    (``stats['interrupted']``), as does a time limit (``stats['stopped_by_time_limit']``).  ``resume``: continue
    these statistics (a copy) with samples ``settings.first_sample`` onward; resuming where a render stopped gives
    the same bits as an uninterrupted render."""
    settings = settings or RenderSettings()
    settings.validate()
    _check_material_strategy(scene, settings)
    if settings.threads is not None:
        numba.set_num_threads(min(settings.threads, numba.config.NUMBA_NUM_THREADS))
    threads = numba.get_num_threads()
    t_setup = time.perf_counter()
    arrays = scene.compile()
    own_tracer = tracer is None
    tracer = tracer or RayTracer(arrays, threads=threads)
    cam = scene.camera.kernel_array()
    width, height = scene.camera.resolution
    n_pixels = width * height
    # scenes lit by an environment map alone keep its measured fast path (decisions.md 12); any emitter, no
    # environment, or several light picks per sample take the general area-light path
    area_path = _takes_area_path(scene, settings)
    settings = settings_for(scene, settings)
    settings.validate()  # the automatic choices may take the sample counts past 64
    m = settings.shading_samples
    pass_samples = settings.pass_samples or default_pass_samples(m)
    spp_pass = max(1, min(settings.spp, pass_samples // n_pixels))
    band = max(1, min(n_pixels, pass_samples // spp_pass))
    if resume is not None and settings.adaptive:
        raise ParameterError("an adaptive render cannot be resumed: its sample counts need the whole pilot first")
    if resume is not None and resume.count.size != n_pixels:
        raise ParameterError(f"cannot resume a render of {resume.count.size} pixels at {width}x{height}")
    acc = resume.copy() if resume is not None else Accumulator(n_pixels)
    if area_path and settings.env_candidates > 1:
        raise ParameterError("env_candidates applies to scenes lit by an environment map alone")
    if settings.mis_compensation and scene.environment is None:
        raise ParameterError("mis_compensation applies to environment maps: this scene has none")
    compensated = settings.mis_compensation
    if compensated is None:  # on diffuse materials, where it wins (decisions.md 21 and 29)
        compensated = DIFFUSE if settings.strategy == "mis" and not area_path else False
    env = (scene.environment or _placeholder_environment()).kernel
    stats = {
        "width": width,
        "height": height,
        "spp_requested": settings.spp,
        "strategy": settings.strategy,
        "heuristic": settings.heuristic,
        "n_bsdf": settings.n_bsdf,
        "n_env": settings.n_env,
        "seed": settings.seed,
        "sampler": settings.sampler,
        "env_candidates": settings.env_candidates,
        "mis_compensation": compensated,
        "light_sampler": settings.light_sampler,
        "lights_per_sample": settings.lights_per_sample,
        "light_strategy": settings.light_strategy,
        "area_lights": 0,
        "threads": threads,
        "spp_per_pass": spp_pass,
        "camera_rays": 0,
        "shadow_rays": 0,
        "embree_rays": 0,
        "passes": 0,
        "interrupted": False,
        "stopped_by_time_limit": False,
        "triangles": scene.triangle_count,
        "adaptive": settings.adaptive,
    }
    largest_pass = max(1, band * spp_pass)
    strategy = STRATEGIES[settings.strategy]
    camera_pass = _camera_pass_for()
    stages = (_shade_setup, *_environment_stages(scene, settings), _shade_finish, _analytic_shadow_stage_for())
    if tracer.mesh_scene:
        stages += (_mesh_shadow_stage_for(),)
    worklists = WORKLISTS
    light_constants = {}
    if area_path:
        from .area_lights import WORKLISTS as AREA_WORKLISTS
        from .area_lights import slot_buffers
        from .area_lights import stages as area_stages

        lights = scene.light_table()
        has_env = scene.environment is not None
        selector = build_selector(
            settings.light_sampler, lights, env_irradiance=scene.environment.irradiance_terms if has_env else None
        )
        stats["area_lights"] = int(lights.kind.shape[0])
        stages = area_stages(bool(tracer.mesh_scene))
        worklists = AREA_WORKLISTS
        light_constants = {
            "lights": lights,
            "sel": selector,
            "has_env": has_env,
            "light_strategy": LIGHT_STRATEGIES[settings.light_strategy],
            "n_light": settings.light_samples,
            "n_per_light": settings.n_env,
        }
    ray_counts = np.zeros((numba.config.NUMBA_NUM_THREADS, 8), np.int64)  # per thread (a row = a cache line)
    constants = {
        "mesh_scene": tracer.mesh_scene,
        "scratch": tracer.scratch,
        "ray_counts": ray_counts,
        "counter": new_counter(),  # for the kernels' chunk claims (_worksharing.py)
        # a camera sample's Sobol' numbers, one row per thread (rows of whole cache lines: 8 slots x 24 bytes)
        "numbers": np.zeros((numba.config.NUMBA_NUM_THREADS, (m + LANES - 1) // LANES * LANES, 3)),
        "s": arrays,
        "env": env,
        "cam": cam,
        "seed": settings.seed,
        "sampler": SAMPLERS[settings.sampler],
        "env_candidates": settings.env_candidates,
        "strategy": strategy,
        "n_bsdf": settings.n_bsdf,
        "n_env": settings.n_env,
        "m": m,
        "beta": HEURISTICS[settings.heuristic],
        "compensate": _compensated_materials(arrays.material_kind, compensated),
        "mis": strategy == MIS,
        **light_constants,
    }

    def make_buffers() -> dict[str, np.ndarray]:
        """Every pass uses leading views of these: memory bounded by one pass."""
        made = _pass_buffers(largest_pass, m, environment_stages=not area_path)
        if area_path:
            made.update(slot_buffers(largest_pass * m))
        return made

    def run_pass(acc: Accumulator, pixels: np.ndarray, spp_now: int, sample_start: int) -> int:
        """One pass over ``pixels`` x ``spp_now`` samples; returns the number of shadow rays traced."""
        n = pixels.size * spp_now
        b = {k: v[: n * m] if v.shape[0] == largest_pass * m else v[:n] for k, v in buffers.items()}
        values = {**constants, **b, "spp_pass": spp_now, "sample_start": sample_start}
        values["pixels"] = pixels
        _launch(camera_pass, values)
        for kernel in stages:
            if kernel in worklists:
                values["todo"] = worklists[kernel](b)
            _launch(kernel, values)
        flags = b["flags"]
        shadow_rays = int(np.count_nonzero(flags))
        values.update(acc_mean=acc.mean, acc_m2=acc.m2, acc_count=acc.count, acc_nonfinite=acc.nonfinite)
        _launch(_accumulate, values)
        return shadow_rays

    def over_image(sample_start: int, spp_now: int):
        """The passes that give every pixel samples sample_start .. sample_start + spp_now - 1."""
        for pixel_start in range(0, n_pixels, band):
            count = min(band, n_pixels - pixel_start)
            yield pass_pixels(pixel_start, count), spp_now, sample_start, pixel_start + count

    def uniform_passes(first: int, spp: int):
        for sample_start, spp_now in _sample_rounds(first, spp, spp_pass):
            yield from over_image(sample_start, spp_now)

    def timed_uniform_passes(first: int, spp: int):
        """The uniform rounds under a time limit, each sized from the time per sample per pixel of the round
        before so that the render ends at the limit, not up to a whole pass after it: a round takes the samples
        that fit in the time left (rounded to the nearest), and none are left once half of one no longer fits.
        The image is the one the same samples give in any rounds: only how many there are follows the clock."""
        round_start = _clock()
        yield from over_image(first, 1)  # every pixel gets a sample before the clock can stop the render
        per_spp = _clock() - round_start
        sample, end = first + 1, first + spp
        while sample < end:
            round_start = _clock()
            left = settings.time_limit - (round_start - start)
            spp_now = min(spp_pass, end - sample, int(left / max(per_spp, 1e-9) + 0.5))
            if spp_now < 1:
                stats["stopped_by_time_limit"] = True
                return
            yield from over_image(sample, spp_now)
            per_spp = (_clock() - round_start) / spp_now
            sample += spp_now

    def passes():
        """(pixels, samples per pixel, first sample index, pixels done) of every pass, in order: the uniform rounds
        over the image (of the pilot, if adaptive), then the adaptive rounds (integrators/adaptive.py).  The
        generator runs as the passes are made, so it sees the time spent and the pilot's statistics."""
        if not settings.adaptive:
            rounds = uniform_passes if settings.time_limit is None else timed_uniform_passes
            yield from rounds(settings.first_sample, settings.spp)
            return
        pilot, replan = adaptive.pilot_spp(settings.spp), None
        if settings.time_limit is None:
            yield from uniform_passes(0, pilot)
            counts = adaptive.sample_counts(acc.mean, acc.m2, acc.count, width, height, settings.spp)
        else:  # a time budget: the pilot doubles while it fits in a share of it, then the rest buys the counts
            pilot, round_start = 1, _clock()
            yield from uniform_passes(0, 1)
            while adaptive.time_pilot_continues(pilot, settings.spp, _clock() - start, settings.time_limit):
                round_start = _clock()
                for sample_start in range(pilot, 2 * pilot, spp_pass):  # samples pilot .. 2 pilot - 1
                    yield from over_image(sample_start, min(spp_pass, 2 * pilot - sample_start))
                pilot *= 2
            # time per sample per pixel from the pilot's last round, the one in full-sized passes
            per_spp = (_clock() - round_start) / max(1, pilot // 2)
            mean_spp = adaptive.budget_mean(pilot, settings.spp, _clock() - start, settings.time_limit, per_spp)
            w = adaptive.relative_noise(acc.mean, acc.m2, acc.count, width, height)
            counts = adaptive.counts_from_noise(w, pilot, mean_spp)
            stats["adaptive_mean_planned"] = mean_spp
            stats["adaptive_pilot_seconds"], stats["adaptive_seconds_per_spp"] = _clock() - start, per_spp
            rounds_start = _clock()

            def replan(done: np.ndarray) -> np.ndarray:
                """The counts again, at the time per camera sample the rounds after the pilot have taken: the
                pilot's price for them (x COST_FACTOR) was only a first guess."""
                affordable = (settings.time_limit - (_clock() - start)) * taken / max(_clock() - rounds_start, 1e-9)
                planned = adaptive.counts_from_noise(w, pilot, settings.spp, done, max(0.0, affordable))
                stats["adaptive_max_spp"] = int(planned.max())
                return planned

        # the plan's largest count (the image's own is spp_max: they differ if the render stops early)
        stats["adaptive_pilot_spp"], stats["adaptive_max_spp"] = pilot, int(counts.max())
        taken = 0  # camera samples after the pilot
        for pixels, spp_now, sample_start in adaptive.sample_rounds(counts, pilot, largest_pass, replan):
            yield pixels, spp_now, sample_start, n_pixels
            taken += pixels.size * spp_now

    counted_before = 0
    start = _clock()
    with _InterruptAtPassEnd() as interrupt:
        try:
            # made under the Ctrl-C handler: populating their pages can take a second or more per GB on this VM,
            # and a Ctrl-C meanwhile waits for the first pass like any other
            buffers = make_buffers()
            # warm up every kernel on one pixel (loads cached machine code) before the clock starts
            run_pass(Accumulator(n_pixels), pass_pixels(0, 1), 1, 0)
            if settings.adaptive:
                adaptive.warm_up()
            if PROFILE is not None:
                PROFILE.clear()  # the warm-up (and any compiling) is not the render
            counted_before = ray_counts.sum()
            stats["setup_seconds"] = time.perf_counter() - t_setup
            start = _clock()
            for pixels, spp_now, sample_start, pixels_done in passes():
                stats["shadow_rays"] += run_pass(acc, pixels, spp_now, sample_start)
                stats["camera_rays"] += pixels.size * spp_now
                stats["passes"] += 1
                stats["seconds"] = _clock() - start
                stats["spp_done"] = int(acc.count.min())
                if progress is not None:
                    progress(dict(stats, spp_target=settings.spp, pixels_done=pixels_done))
                if stats["spp_done"] < 1:
                    continue  # a stop waits until every pixel holds a sample (the first round is 1 spp)
                if interrupt.requested:
                    raise KeyboardInterrupt
                if settings.time_limit is not None and stats["seconds"] >= settings.time_limit:
                    stats["stopped_by_time_limit"] = True
                    raise _Stop
        except _Stop:
            pass  # pixels of the unfinished pass have one pass fewer: their counts say so
        except KeyboardInterrupt:
            stats["interrupted"] = True
    stats["seconds"] = _clock() - start
    stats["embree_rays"] = int(ray_counts.sum() - counted_before)  # every Embree call of a render is in a kernel
    if own_tracer:
        tracer.close()
    return _finish(acc, stats, width, height)


def _environment_stages(scene: Scene, settings: RenderSettings) -> tuple:
    """The environment path's sampling, coordinates and radiance stages for ``scene``: 8 slots at a time in vector
    IR where the map allows it (emitters/envmap_lanes.py, decisions.md 42, 43), else one slot at a time."""
    k = scene.environment.kernel if scene.environment is not None else None
    if settings.env_candidates > 1:
        sample_stage = _env_resample_stage
    elif k is not None and samples_in_lanes(k):
        sample_stage = _env_sample_lanes_stage
    else:
        sample_stage = _env_sample_stage
    in_lanes = k is not None and lanes_apply(k.image, k.lookup == BILINEAR)
    coords_stage = _env_coords_lanes_stage if k is not None and coords_in_lanes(k) else _env_coords_stage
    return sample_stage, coords_stage, _env_radiance_stage if in_lanes else _env_radiance_scalar_stage


def _analytic_shadow_stage_for():
    """The analytic shadow stage in lanes where this Numba's LLVM builds the intrinsics, else the scalar one."""
    return _analytic_shadow_stage if lanes_compile() else _analytic_shadow_scalar_stage


def _mesh_shadow_stage_for():
    """The mesh shadow stage in Embree's 8-ray packets where they are native, else one ray at a time."""
    return _mesh_shadow_stage if packets_native() else _mesh_shadow_single_stage


def _camera_pass_for():
    """The camera pass with its analytic hits in lanes where this Numba's LLVM builds the intrinsics, else the
    scalar one."""
    return _camera_pass if lanes_compile() else _camera_scalar_pass


def kernels_cached(scene: Scene | None = None, settings: RenderSettings | None = None) -> bool:
    """Whether the kernels a render of ``scene`` with ``settings`` takes (by default the demo's: an environment-lit
    scene with a mesh) are in the on-disk cache; else the first render compiles them, ~20-45 s."""
    from .._numba import is_cached

    if scene is None:
        from ..demo import demo_scene

        scene = demo_scene()
    settings = settings or RenderSettings()
    meshes = scene.triangle_count > 0
    if _takes_area_path(scene, settings):
        from .area_lights import stages as area_stages

        shading = area_stages(meshes)
    else:
        shading = (
            _shade_setup,
            *_environment_stages(scene, settings_for(scene, settings)),
            _shade_finish,
            _analytic_shadow_stage_for(),
        )
        shading += (_mesh_shadow_stage_for(),) if meshes else ()
    return is_cached(_camera_pass_for(), *shading, _accumulate)


class _Stop(Exception):
    """The time limit was reached."""


def _sample_rounds(first: int, spp: int, spp_pass: int):
    """(first sample index, samples per pixel) of each round over the image: one sample first, so that a stop
    (Ctrl-C, a time limit) soon after the start still leaves every pixel with a sample, then ``spp_pass`` at a
    time.  The rounds change nothing in the image: each sample's random numbers depend on its index alone."""
    yield first, 1
    for start in range(1, spp, spp_pass):
        yield first + start, min(spp_pass, spp - start)


class _InterruptAtPassEnd:
    """While rendering in the main thread, the first Ctrl-C asks the render to stop at the end of the pass in
    flight (no finished work is thrown away, and never before every pixel has a sample); a second Ctrl-C
    interrupts at once, keeping what has been accumulated.  Elsewhere (a worker thread) Ctrl-C is left alone."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def _handler(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __enter__(self):
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc):
        import signal

        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False


def _finish(acc: Accumulator, stats: dict, width: int, height: int) -> RenderResult:
    counts = acc.count
    samples = int(counts.sum())
    seconds = max(stats.get("seconds", 0.0), 1e-12)
    rays = stats["camera_rays"] + stats["shadow_rays"]
    stats.update(
        spp_done=int(counts.min()),
        spp_max=int(counts.max()),
        camera_samples=samples,
        samples_per_s=samples / seconds,
        rays=rays,
        rays_per_s=rays / seconds,
        nonfinite_samples=int(acc.nonfinite.sum()),
    )
    return result_from(acc, width, height, stats)


def result_from(acc: Accumulator, width: int, height: int, stats: dict | None = None) -> RenderResult:
    """The image (float32 mean, never NaN/Inf), the variance of each pixel's mean, and the counts of ``acc``."""
    counts = acc.count
    if counts.size != width * height:
        raise ParameterError(f"{counts.size} pixels are not a {width}x{height} image")
    with np.errstate(divide="ignore", invalid="ignore"):
        var = np.where((counts >= 2)[:, None], acc.m2 / (counts * np.maximum(counts - 1, 1))[:, None], 0.0)
    image = np.nan_to_num(acc.mean.reshape(height, width, 3), nan=0.0, posinf=0.0, neginf=0.0)
    return RenderResult(
        image.astype(np.float32),
        np.nan_to_num(var.reshape(height, width, 3), nan=0.0, posinf=0.0).astype(np.float32),
        counts.reshape(height, width),
        stats if stats is not None else {},
        acc,
    )
