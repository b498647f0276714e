"""The estimator's vocabulary: technique and slot codes, which random numbers each slot takes, directions from
BSDF or hemisphere sampling, and the MIS share of each technique's samples.

A camera sample has ``m`` shading *slots*; slot r = k m + j is shading sample j of camera sample k, and its state
says which technique made its direction.  Shadow-ray flags say what became of the ray.
"""

from __future__ import annotations

from .._numba import jit, jit_inline
from ..bsdfs.dispatch import bsdf_sample
from ..geometry.frame import coordinate_system, to_local
from ..geometry.intersect import surface
from ..sampling.kernels import INV_2PI, cosine_hemisphere_pdf, square_to_cosine_hemisphere, square_to_uniform_hemisphere
from ..sampling.mis import mis_weight, mis_weight_over, mis_weight_share
from ..sampling.rng import group_slot, uniform

__all__ = [
    "STRATEGIES",
    "bsdf_share",
    "light_scale",
    "load_shading_frame",
    "pick_number",
    "sample_direction",
    "store_shading_frame",
    "technique_slot",
]

#: the renderer's strategies (``env`` samples the lights: the environment, area, point, spot and directional lights)
STRATEGIES = {"uniform": 0, "cosine": 1, "brdf": 2, "env": 3, "mis": 4}
UNIFORM, COSINE, BRDF, ENV, MIS = range(5)
# slot states: empty, a BSDF sample, a light sample, a hemisphere sample
SLOT_NONE, SLOT_BSDF, SLOT_LIGHT, SLOT_HEMI = 0, 1, 2, 3
# flags of a shading sample's shadow ray: no ray, unblocked, to be tested against meshes, blocked, to be tested
# against the analytic shapes (and then the meshes' boxes)
NONE, VISIBLE, TEST_MESH, BLOCKED, TEST_ANALYTIC = 0, 1, 2, 3, 4


@jit_inline
def technique_slot(state, strategy, n_bsdf, n_env, j):
    """The (sample state, slot) whose random numbers shading slot j of a camera sample takes: under MIS the
    ``n_bsdf`` BSDF slots form one group and the ``n_env`` light slots another, a single technique's slots one
    group (``sampling.rng.group_slot``: a group's directions in a pixel are one stratified set)."""
    if strategy == MIS:
        if j < n_bsdf:
            return group_slot(state, 0, n_bsdf, j)
        return group_slot(state, n_bsdf, n_env, j - n_bsdf)
    return group_slot(state, 0, n_bsdf + n_env, j)


@jit
def pick_slot(state, n_bsdf, n_per_light, m, strategy, j):
    """The (sample state, slot) whose 1D number picks the light for light slot j: under ``sobol`` the K picks of a
    camera sample are one stratified group (``sampling.rng.group_slot``), under ``independent`` the first slot of
    j's ``n_per_light`` takes it."""
    if strategy == MIS:
        return group_slot(state, n_bsdf, (m - n_bsdf) // n_per_light, (j - n_bsdf) // n_per_light, n_per_light)
    return group_slot(state, 0, m, j)


@jit
def pick_number(state, n_bsdf, n_per_light, m, strategy, j, u0):
    """The number that picks the light for light slot j whose 2D pair begins with u0.  With one sample per picked
    light, u0 itself (Mitsuba 3's ``sample_reuse``): the selector hands back what is left of it to sample the light,
    so the samples that go to one light keep the pair's stratification; a separate number (the layout's 1D choice of
    :func:`pick_slot`) left each light a random subset of the net (decisions.md 74: relMSE 5.99e-4 -> 5.90e-4 on
    the area scene).  With ``n_per_light`` > 1 the group's slots share one pick, which their pairs cannot all make:
    the 1D number."""
    if n_per_light == 1:
        return u0
    rp, picker = pick_slot(state, n_bsdf, n_per_light, m, strategy, j)
    return uniform(rp, 4 + 3 * picker)


@jit_inline
def bsdf_share(c, p_bsdf, p_light):
    """The share of a BSDF (or hemisphere) sample's f L cos / p in its camera sample's estimate: 1 / m for a single
    technique; under MIS its weight against the lights, divided by its count (balance or power heuristic on
    sample-count-weighted densities, sampling/mis.py: n_bsdf p_bsdf against K N p_l p_li)."""
    if c.strategy != MIS:
        return 1.0 / c.m
    return mis_weight_share(c.n_bsdf, p_bsdf, c.n_light, p_light, c.beta)


@jit_inline
def light_scale(c, cos_wi, pdf, p_bsdf, p_source):
    """The factor of a light sample's f L: cos / (p m) for a single technique; under MIS cos times its weight
    against the BSDF's samples over its density (one division, sampling/mis.py), with ``p_bsdf`` 0 for a delta
    light (weight 1).  A resampled sample (``p_source`` > 0: the density it was drawn from) weighs with that density
    and divides by its effective one (``integrators/stages/light_samples.py``)."""
    if c.strategy != MIS:
        return cos_wi / pdf * (1.0 / c.m)
    if p_source > 0.0:
        return cos_wi / pdf * mis_weight(c.n_light, p_source, c.n_bsdf, p_bsdf, c.beta) / c.n_light
    return cos_wi * mis_weight_over(c.n_light, pdf, c.n_bsdf, p_bsdf, c.beta)


@jit_inline
def sample_direction(technique, mk, mp, wo, u0, u1, u2):
    """A local direction from BSDF (``BRDF``) or hemisphere (``UNIFORM``, ``COSINE``) sampling:
    (slot state, wi, pdf, BSDF sample weight f cos / pdf); state ``SLOT_NONE`` when the technique declines.
    (u0, u1) is the slot's 2D pair and u2 its 1D choice (the sampler's layout, ``sampling/rng.py``); the BSDFs take
    the lobe choice first, so the pair must reach them as their direction (u1, u2), or a QMC sampler's 2D
    stratification is lost for BSDF directions."""
    if technique == BRDF:
        wi, pdf, w = bsdf_sample(mk, mp, wo, u2, u0, u1)
        if pdf <= 0.0 or (w[0] == 0.0 and w[1] == 0.0 and w[2] == 0.0):
            return SLOT_NONE, wi, 0.0, w
        return SLOT_BSDF, wi, pdf, w
    if technique == UNIFORM:
        wi = square_to_uniform_hemisphere(u0, u1)
        pdf = INV_2PI
    else:
        wi = square_to_cosine_hemisphere(u0, u1)
        pdf = cosine_hemisphere_pdf(wi[0], wi[1], wi[2])
    if wi[2] <= 0.0 or pdf <= 0.0:
        return SLOT_NONE, wi, 0.0, (0.0, 0.0, 0.0)
    return SLOT_HEMI, wi, pdf, (0.0, 0.0, 0.0)


@jit_inline
def store_shading_frame(s, k, hit, ox, oy, oz, dx, dy, dz, point, gnormal, point_error, frame, wo_local, material):
    """Rebuild camera sample k's hit (``hit`` = kind, index, prim, b1, b2, t), orient a two-sided surface toward
    the viewer, and store its point, geometric normal, error bound (how far rays leaving it move their origin,
    ``intersect.ray_offset``), shading frame (s, t, n), local ``wo`` and material.  Returns (p, ng, error, wo), or
    ``wo[2] <= 0`` when the viewer is below a one-sided surface (nothing to shade)."""
    kind, index, prim, b1, b2, t = hit
    p, ng, ns, mat, two_sided, error = surface(s, kind, index, prim, b1, b2, ox, oy, oz, dx, dy, dz, t)
    if two_sided == 1 and -(dx * ng[0] + dy * ng[1] + dz * ng[2]) < 0.0:
        ng = (-ng[0], -ng[1], -ng[2])
        ns = (-ns[0], -ns[1], -ns[2])
    ts, tt = coordinate_system(ns[0], ns[1], ns[2])
    wo = to_local(ts, tt, ns, -dx, -dy, -dz)
    if wo[2] <= 0.0:  # seen from below a one-sided surface: black
        return p, ng, error, wo
    point_error[k] = error
    for c in range(3):
        point[k, c] = p[c]
        gnormal[k, c] = ng[c]
        frame[k, c] = ts[c]
        frame[k, 3 + c] = tt[c]
        frame[k, 6 + c] = ns[c]
        wo_local[k, c] = wo[c]
    material[k] = mat
    return p, ng, error, wo


@jit
def load_shading_frame(frame, wo_local, k):
    """What :func:`store_shading_frame` stored for camera sample k: its shading frame (s, t, n) and local ``wo``.
    (The material stays with the caller: Numba's parfor array analysis rejects an inlined function that returns the
    material's parameter block, an array view, in a tuple -- "Dimension mismatch".)"""
    ts = (frame[k, 0], frame[k, 1], frame[k, 2])
    tt = (frame[k, 3], frame[k, 4], frame[k, 5])
    ns = (frame[k, 6], frame[k, 7], frame[k, 8])
    return ts, tt, ns, (wo_local[k, 0], wo_local[k, 1], wo_local[k, 2])
