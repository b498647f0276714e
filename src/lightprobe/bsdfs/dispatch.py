"""One dispatching kernel per BSDF operation: ``kind`` selects the material, ``p`` is its parameter block.

The renderer's kernels call :func:`bsdf_eval`, :func:`bsdf_pdf` and :func:`bsdf_sample`; the Python methods of
:class:`~lightprobe.bsdfs.base.BSDF` call the batch versions below, so both run the same code.
"""

from __future__ import annotations

import numpy as np

from .._numba import jit, jit_inline
from .._worksharing import in_threads
from .base import BATCHES
from .conductor import GGX_CONDUCTOR, ggx_conductor_eval, ggx_conductor_pdf, ggx_conductor_sample
from .lambert import LAMBERT, lambert_eval, lambert_pdf, lambert_sample, lambert_textured
from .metallic_roughness import (
    METALLIC_ROUGHNESS,
    metallic_roughness_eval,
    metallic_roughness_pdf,
    metallic_roughness_sample,
    metallic_roughness_textured,
)
from .phong import PHONG, phong_eval, phong_pdf, phong_sample
from .plastic import PLASTIC, plastic_eval, plastic_pdf, plastic_sample

__all__ = ["bsdf_eval", "bsdf_pdf", "bsdf_sample", "bsdf_textured", "eval_batch", "pdf_batch", "sample_batch"]


@jit_inline
def bsdf_eval(kind, p, wo, wi):
    if kind == LAMBERT:
        return lambert_eval(p, wo, wi)
    if kind == PHONG:
        return phong_eval(p, wo, wi)
    if kind == GGX_CONDUCTOR:
        return ggx_conductor_eval(p, wo, wi)
    if kind == PLASTIC:
        return plastic_eval(p, wo, wi)
    if kind == METALLIC_ROUGHNESS:
        return metallic_roughness_eval(p, wo, wi)
    return 0.0, 0.0, 0.0


@jit_inline
def bsdf_pdf(kind, p, wo, wi):
    if kind == LAMBERT:
        return lambert_pdf(p, wo, wi)
    if kind == PHONG:
        return phong_pdf(p, wo, wi)
    if kind == GGX_CONDUCTOR:
        return ggx_conductor_pdf(p, wo, wi)
    if kind == PLASTIC:
        return plastic_pdf(p, wo, wi)
    if kind == METALLIC_ROUGHNESS:
        return metallic_roughness_pdf(p, wo, wi)
    return 0.0


@jit_inline
def bsdf_sample(kind, p, wo, u0, u1, u2):
    """Returns (wi, pdf, weight = f cos / pdf)."""
    if kind == LAMBERT:
        return lambert_sample(p, wo, u0, u1, u2)
    if kind == PHONG:
        return phong_sample(p, wo, u0, u1, u2)
    if kind == GGX_CONDUCTOR:
        return ggx_conductor_sample(p, wo, u0, u1, u2)
    if kind == PLASTIC:
        return plastic_sample(p, wo, u0, u1, u2)
    if kind == METALLIC_ROUGHNESS:
        return metallic_roughness_sample(p, wo, u0, u1, u2)
    return (0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0)


@jit_inline
def bsdf_textured(kind, p, out, r, g, b, metallic, roughness):
    """Write into ``out`` (length ``TEXTURED_PARAM_SIZE``) material ``p``'s block at a hit whose textures read base
    colour (r, g, b), metallic and roughness factors (1 where a material has no such texture)."""
    for i in range(out.shape[0]):
        out[i] = p[i]
    if kind == LAMBERT:
        lambert_textured(out, r, g, b)
    elif kind == METALLIC_ROUGHNESS:
        metallic_roughness_textured(p, out, r, g, b, metallic, roughness)


# The batches: serial range kernels that ``_worksharing.in_threads`` runs in threads (as ``prange`` loops around the
# inlined dispatch, from an empty cache, eval_batch compiled in 3.9 s, now 1.9 s; pdf 1.2 -> 0.7 s, sample 4.0 ->
# 3.1 s: decisions.md 130); any split of the rows gives the same values.
@jit
def _eval_range(kind, p, wo, wi, out, lo, hi):
    for i in range(lo, hi):
        f = bsdf_eval(kind, p, (wo[i, 0], wo[i, 1], wo[i, 2]), (wi[i, 0], wi[i, 1], wi[i, 2]))
        out[i, 0], out[i, 1], out[i, 2] = f


def eval_batch(kind, p, wo, wi):
    out = np.empty((wi.shape[0], 3))
    in_threads(_eval_range, wi.shape[0], kind, p, wo, wi, out)
    return out


@jit
def _pdf_range(kind, p, wo, wi, out, lo, hi):
    for i in range(lo, hi):
        out[i] = bsdf_pdf(kind, p, (wo[i, 0], wo[i, 1], wo[i, 2]), (wi[i, 0], wi[i, 1], wi[i, 2]))


def pdf_batch(kind, p, wo, wi):
    out = np.empty(wi.shape[0])
    in_threads(_pdf_range, wi.shape[0], kind, p, wo, wi, out)
    return out


@jit
def _sample_range(kind, p, wo, u, wi, pdf, weight, lo, hi):
    for i in range(lo, hi):
        d, pr, w = bsdf_sample(kind, p, (wo[i, 0], wo[i, 1], wo[i, 2]), u[i, 0], u[i, 1], u[i, 2])
        wi[i, 0], wi[i, 1], wi[i, 2] = d
        pdf[i] = pr
        weight[i, 0], weight[i, 1], weight[i, 2] = w


def sample_batch(kind, p, wo, u):
    n = u.shape[0]
    wi, pdf, weight = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    in_threads(_sample_range, n, kind, p, wo, u, wi, pdf, weight)
    return wi, pdf, weight


BATCHES[:] = [eval_batch, pdf_batch, sample_batch]  # the BSDF classes' methods run these (base.py)
