"""The state of one pass, declared once: what the stages read (:class:`PassConstants`) and the arrays they write,
grouped by owner (:class:`CameraSamples`, one row per camera sample; :class:`Slots`, one row per shading slot).

pbrt-v4 declares each wavefront queue's fields in one place (``wavefront/workitems.soa``) and its kernels follow
from it; here the records are NamedTuples of arrays that every stage body takes whole, reads by field name and
writes through (``stages/``).  A pass holds ``n`` camera samples with ``m`` shading slots each: slot ``r = k m + j``
is shading sample ``j`` of camera sample ``k``.

Fields a render does not need are empty arrays of the same type (so every render compiles the same kernels):
``Slots.light`` in scenes lit by an environment map alone (no light is picked), ``Slots.seg`` in scenes without
bounded lights (every shadow ray is unbounded), the BSDF rays' hit fields in scenes without emissive surfaces (a BSDF
ray there needs a shadow test, not its nearest hit).  A stage that writes one of them checks that it is there.

Buffers are made once per render for its largest pass (mapped without huge pages and populated when made:
decisions.md 32, 39); each pass takes leading views of them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._memory import fresh_array
from ..bsdfs.base import TEXTURED_PARAM_SIZE

__all__ = ["AccumulatorArrays", "CameraSamples", "PassConstants", "Slots", "camera_buffers", "slot_buffers", "views"]


class PassConstants(NamedTuple):
    """What every stage of a render reads and none writes (but the per-thread scratch rows), with the pass's own
    range (``pixels``, ``spp_pass``, ``sample_start``) replaced pass by pass."""

    sampler: int  # sampling.rng.SAMPLERS
    seed: int
    strategy: int  # techniques.STRATEGIES
    n_bsdf: int  # BSDF (or hemisphere) slots per camera sample under MIS
    n_light: int  # light slots per camera sample: lights_per_sample x n_per_light (the lecture's K N)
    n_per_light: int  # samples of each picked light (N)
    m: int  # slots per camera sample
    beta: float  # MIS heuristic exponent: 1 balance, 2 power
    light_strategy: int  # emitters.area.STRATEGIES: how an area light is sampled
    env_candidates: int  # > 1: resampled environment samples (RIS)
    bsdf_weighed: bool  # the BSDF-ray stages weigh a BSDF ray's radiance for MIS (all but environment-alone scenes)
    compensate: np.ndarray  # (materials,) bool: the compensated environment density for this material
    cam: np.ndarray  # geometry.camera.Camera.kernel_array()
    mesh_scene: int  # Embree scene handle (0: no meshes)
    scratch: np.ndarray  # Embree's per-thread scratch rows (geometry/embree.py)
    ray_counts: np.ndarray  # (threads, 8) int64: rays sent to Embree per thread (a row = a cache line)
    numbers: np.ndarray  # (threads, SETUP_RUN x m rounded up to 8, 3): a run's Sobol' numbers (stages/setup.py)
    packet_slots: np.ndarray  # (threads, 8) int64: the slots of a thread's packet of shadow rays, or of its lane_rays
    lane_rays: np.ndarray  # (threads, ray_lanes.FIELDS, 8) float64: a thread's block of 8 rays and their hits
    pixels: np.ndarray  # the pass's pixels, in buffer order (schedule.pass_pixels)
    spp_pass: int  # samples per pixel in this pass
    sample_start: int  # sample index of the pass's first sample of each pixel
    # directly seen emitters' outlines (integrators/outlines.py's OutlineTable; all empty: none)
    outline_start: np.ndarray  # (pixels + 1,) int64: pixel p's entries start[p] .. start[p + 1] - 1
    outline_shape: np.ndarray  # (entries,) int64
    outline_cover: np.ndarray  # (entries,) float64
    outline_geom: np.ndarray  # (shapes, 13) float64
    outline_radiance: np.ndarray  # (shapes, 3) float64


class CameraSamples(NamedTuple):
    """One row per camera sample k = q spp_pass + i (pixel q of the pass, its sample i)."""

    dirs: np.ndarray  # (n, 3) camera ray direction
    t: np.ndarray  # (n,) nearest hit distance (inf: a miss)
    kind: np.ndarray  # (n,) int64 geometry.intersect MISS / MESH / SPHERE / RECT
    index: np.ndarray  # (n,) int64 which mesh, sphere or rectangle
    prim: np.ndarray  # (n,) int64 mesh face
    b1: np.ndarray  # (n,) barycentrics of a mesh hit
    b2: np.ndarray
    direct: np.ndarray  # (n, 3) radiance the camera ray sees (an emitter, the environment)
    point: np.ndarray  # (n, 3) hit point
    gnormal: np.ndarray  # (n, 3) geometric normal, toward the viewer on two-sided surfaces
    point_error: np.ndarray  # (n,) the point's error bound along it (intersect.ray_offset)
    frame: np.ndarray  # (n, 9) shading frame s, t, n
    wo_local: np.ndarray  # (n, 3) direction to the viewer in the shading frame
    material: np.ndarray  # (n,) int64; -1: nothing to shade
    params: np.ndarray  # (n, TEXTURED_PARAM_SIZE) or empty: a textured material's block at the hit (textures/)


class Slots(NamedTuple):
    """One row per shading slot r = k m + j."""

    state: np.ndarray  # (nm,) int8 techniques.SLOT_*: which technique made the direction
    wdir: np.ndarray  # (nm, 3) direction (world); after the finish stage, the shadow ray's
    wloc: np.ndarray  # (nm, 3) direction in the shading frame (hemisphere samples)
    tpdf: np.ndarray  # (nm,) density of the technique that made it (a light's x its selection probability)
    bweight: np.ndarray  # (nm, 3) a BSDF sample's f cos / pdf
    radiance: np.ndarray  # (nm, 3) radiance arriving along the direction
    contrib: np.ndarray  # (nm, 3) unoccluded contribution
    flags: np.ndarray  # (nm,) int8 techniques NONE / VISIBLE / TEST_MESH / BLOCKED / TEST_ANALYTIC
    u: np.ndarray  # (nm, 2) a light slot's 2D pair
    uv: np.ndarray  # (nm, 2) lat-long coordinates of the direction (environment lookups)
    light_pdf: np.ndarray  # (nm,) a BSDF slot: the lights' density there for MIS (-1: radiance already weighted);
    #                        a resampled light slot: the density it was drawn from
    seg: np.ndarray  # (nm,) or empty: the distance to a light slot's sampled point (inf: unbounded)
    light: np.ndarray  # (nm,) int64 or empty: the light a light slot sampled (its row of the light table)
    ray_o: np.ndarray  # (nm, 3) or empty: a BSDF ray's origin (offset from the surface) ...
    hit_t: np.ndarray  # ... and its nearest hit, or empty
    hit_kind: np.ndarray
    hit_index: np.ndarray
    hit_prim: np.ndarray
    hit_b1: np.ndarray
    hit_b2: np.ndarray
    hit_mesh: np.ndarray  # (nm,) bool: a mesh may be nearer than the analytic hit
    # (nm,) or empty (a render that learns its light selection: emitters/selection_learning.py): -1 where the slot
    # picked no light; after the light samples, the pick's probability; after the finish stage, the luminance of
    # f L cos / the density of the point on the light (0 for a sample that gives nothing)
    learn: np.ndarray


class AccumulatorArrays(NamedTuple):
    """Per-pixel running statistics (integrators/accumulation.py's Accumulator)."""

    mean: np.ndarray  # (pixels, 3) float64
    m2: np.ndarray  # (pixels, 3) sum of squared deviations (Welford)
    count: np.ndarray  # (pixels,) int64
    nonfinite: np.ndarray  # (pixels,) int64


def camera_buffers(n: int, *, textured: bool = False) -> CameraSamples:
    """Buffers for ``n`` camera samples; ``textured``: the scene has textured materials (``params``)."""
    i64 = np.int64
    return CameraSamples(
        fresh_array((n, 3)),
        fresh_array(n),
        fresh_array(n, i64),
        fresh_array(n, i64),
        fresh_array(n, i64),
        fresh_array(n),
        fresh_array(n),
        fresh_array((n, 3)),
        fresh_array((n, 3)),
        fresh_array((n, 3)),
        fresh_array(n),
        fresh_array((n, 9)),
        fresh_array((n, 3)),
        fresh_array(n, i64),
        fresh_array((n if textured else 0, TEXTURED_PARAM_SIZE)),
    )


def slot_buffers(nm: int, *, picks: bool, bounded_shadows: bool, bsdf_hits: bool, learning: bool = False) -> Slots:
    """Buffers for ``nm`` slots; ``picks``: light slots pick a light (``light``); ``bounded_shadows``: shadow rays
    may end at a light (``seg``); ``bsdf_hits``: BSDF rays look for their nearest hit (the hit fields);
    ``learning``: the render learns its light selection (``learn``)."""
    shadow = nm if bounded_shadows else 0
    picked = nm if picks else 0
    hits = nm if bsdf_hits else 0
    i64 = np.int64
    return Slots(
        fresh_array(nm, np.int8),
        fresh_array((nm, 3)),
        fresh_array((nm, 3)),
        fresh_array(nm),
        fresh_array((nm, 3)),
        fresh_array((nm, 3)),
        fresh_array((nm, 3)),
        fresh_array(nm, np.int8),
        fresh_array((nm, 2)),
        fresh_array((nm, 2)),
        fresh_array(nm),
        fresh_array(shadow),
        fresh_array(picked, i64),
        fresh_array((hits, 3)),
        fresh_array(hits),
        fresh_array(hits, i64),
        fresh_array(hits, i64),
        fresh_array(hits, i64),
        fresh_array(hits),
        fresh_array(hits),
        fresh_array(hits, np.bool_),
        fresh_array(nm if learning else 0),
    )


def views(record, rows: int):
    """The leading ``rows`` rows of every non-empty array of ``record`` (a pass smaller than the largest)."""
    return type(record)(*(a[:rows] if a.shape[0] else a for a in record))
