"""A pass's camera samples for the laboratory's estimators: camera rays, the core's random numbers laid out as its
shading slots, and the hits' shading points (the render core's own routines), for :mod:`lightprobe.lab.render`'s
estimator of environment-lit scenes, :mod:`lightprobe.lab.light_render`'s of scenes with lights, and the light
choice's measurements (``experiments/light_choice.py``)."""

from __future__ import annotations

import numpy as np

from .._numba import jit
from .._worksharing import in_threads
from ..geometry.camera import camera_batch
from ..geometry.intersect import MISS
from ..integrators.techniques import store_shading_frame
from ..sampling.rng import group_slot, sample_state, uniform
from .technique_errors import TechniqueError

__all__ = ["camera_batch", "require_untextured", "shading_batch", "technique_numbers"]


# Range kernels run by threads (``_worksharing.in_threads``), not ``prange`` loops: the same values (each item is its
# own), and Numba's parallel-loop passes made them slow to compile (``shading_batch`` alone 7.8 s; decisions.md 129).
@jit
def _numbers_range(sampler, seed, pixels, sample, first, count, dims, out, lo, hi):
    for k in range(lo, hi):
        state = sample_state(sampler, seed, pixels[k], sample)
        for i in range(count):
            member, slot = group_slot(state, first, count, i)
            for d in range(dims):
                out[i, k, d] = uniform(member, 2 + 3 * slot + d)


def technique_numbers(sampler, seed, pixels, sample, first, count, dims):
    """(count, N, dims) numbers of a technique's ``count`` samples per camera sample, laid out as the core lays out
    a group of shading slots (``integrators.techniques.technique_slot``): under ``sobol`` the group shares the first
    slot's dimensions and member i of sample k takes sample index k count + i, so a pixel's samples of one technique
    are one stratified Sobol' set; under ``independent`` member i takes slot ``first + i``."""
    n = pixels.shape[0]
    out = np.empty((count, n, dims))
    in_threads(_numbers_range, n, sampler, seed, pixels, sample, first, count, dims, out)
    return out


@jit
def _shading_range(s, kind, index, prim, b1, b2, t, cam_origin, dirs, point, gnormal, error, frame, wo_local, material,
                   lo, hi):  # fmt: skip
    ox, oy, oz = cam_origin[0], cam_origin[1], cam_origin[2]
    for k in range(lo, hi):
        if kind[k] == MISS:
            continue
        hit = (kind[k], index[k], prim[k], b1[k], b2[k], t[k])
        store_shading_frame(
            s, k, hit, ox, oy, oz, dirs[k, 0], dirs[k, 1], dirs[k, 2], point, gnormal, error, frame, wo_local, material
        )


def shading_batch(s, kind, index, prim, b1, b2, t, cam_origin, dirs):
    """Point, geometric normal, error bound, shading frame (N, 9), local wo and material (-1: nothing to shade)."""
    n = dirs.shape[0]
    point = np.zeros((n, 3))
    gnormal = np.zeros((n, 3))
    error = np.zeros(n)
    frame = np.zeros((n, 9))
    wo_local = np.zeros((n, 3))
    material = np.full(n, -1, np.int64)
    outputs = (point, gnormal, error, frame, wo_local, material)
    in_threads(_shading_range, n, s, kind, index, prim, b1, b2, t, cam_origin, dirs, *outputs)
    return outputs


def require_untextured(scene, who: str) -> None:
    """The shading points here carry the materials' untextured parameters: a scene with a textured material is an
    error naming it (``who`` renders it)."""
    textured = [name for name, material in scene.materials.items() if material.textures is not None]
    if textured:
        raise TechniqueError(f"scene {scene.name!r}: {who} render untextured materials; {textured[0]!r} has textures")
