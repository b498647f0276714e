"""A pass's camera samples for the laboratory's estimators: camera rays, the core's random numbers laid out as its
shading slots, and the hits' shading points (the render core's own routines), for :mod:`lightprobe.lab.render`'s
estimator of environment-lit scenes, :mod:`lightprobe.lab.light_render`'s of scenes with lights, and the light
choice's measurements (``experiments/light_choice.py``)."""

from __future__ import annotations

import numpy as np

from .._numba import jit_parallel, prange
from ..geometry.camera import camera_ray
from ..geometry.intersect import MISS
from ..integrators.techniques import store_shading_frame
from ..sampling.rng import group_slot, sample_state, uniform
from .technique_errors import TechniqueError

__all__ = ["camera_batch", "require_untextured", "shading_batch", "technique_numbers"]


@jit_parallel
def camera_batch(cam, pixels, jitter):
    out = np.empty((pixels.shape[0], 3))
    for i in prange(pixels.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = camera_ray(cam, pixels[i], jitter[i, 0], jitter[i, 1])
    return out


@jit_parallel
def technique_numbers(sampler, seed, pixels, sample, first, count, dims):
    """(count, N, dims) numbers of a technique's ``count`` samples per camera sample, laid out as the core lays out
    a group of shading slots (``integrators.techniques.technique_slot``): under ``sobol`` the group shares the first
    slot's dimensions and member i of sample k takes sample index k count + i, so a pixel's samples of one technique
    are one stratified Sobol' set; under ``independent`` member i takes slot ``first + i``."""
    n = pixels.shape[0]
    out = np.empty((count, n, dims))
    for k in prange(n):
        state = sample_state(sampler, seed, pixels[k], sample)
        for i in range(count):
            member, slot = group_slot(state, first, count, i)
            for d in range(dims):
                out[i, k, d] = uniform(member, 2 + 3 * slot + d)
    return out


@jit_parallel
def shading_batch(s, kind, index, prim, b1, b2, t, cam_origin, dirs):
    """Point, geometric normal, error bound, shading frame (N, 9), local wo and material (-1: nothing to shade)."""
    n = dirs.shape[0]
    point = np.zeros((n, 3))
    gnormal = np.zeros((n, 3))
    error = np.zeros(n)
    frame = np.zeros((n, 9))
    wo_local = np.zeros((n, 3))
    material = np.full(n, -1, np.int64)
    ox, oy, oz = cam_origin[0], cam_origin[1], cam_origin[2]
    for k in prange(n):
        if kind[k] == MISS:
            continue
        hit = (kind[k], index[k], prim[k], b1[k], b2[k], t[k])
        store_shading_frame(
            s, k, hit, ox, oy, oz, dirs[k, 0], dirs[k, 1], dirs[k, 2], point, gnormal, error, frame, wo_local, material
        )
    return point, gnormal, error, frame, wo_local, material


def require_untextured(scene, who: str) -> None:
    """The shading points here carry the materials' untextured parameters: a scene with a textured material is an
    error naming it (``who`` renders it)."""
    textured = [name for name, material in scene.materials.items() if material.textures is not None]
    if textured:
        raise TechniqueError(f"scene {scene.name!r}: {who} render untextured materials; {textured[0]!r} has textures")
