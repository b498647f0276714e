"""The BSDF interface shared by every material, and the parameter block the Numba kernels read.

Conventions (pbrt's): directions are unit vectors in the local shading frame, the normal on +z; ``wo`` points
toward the viewer, ``wi`` toward the light.  ``eval`` is the BRDF value f(wo, wi) without the cosine; ``pdf`` and
the pdf from ``sample`` are per steradian over the whole sphere (a sampler may produce directions below the
horizon, whose value is 0: they are valid samples of its density).  All materials are one-sided: f = 0 unless
both directions are above the surface, and nothing is sampled when ``wo`` is below it (pdf 0).

``u`` has three columns: columns 1 and 2 drive the warp, and a material with two lobes picks one by column 2,
rescaled into the chosen lobe's share of [0, 1) (:func:`lightprobe.sampling.distributions.choose_rescaled`), so that
a stratified pair stays stratified in each lobe.  Column 0, a number of its own, is not used by today's materials
(it chose the lobe until decisions.md 67).

Every material is a kind (an integer) and a fixed-size float64 parameter block; one dispatching kernel per
operation (:mod:`lightprobe.bsdfs.dispatch`) serves these Python methods and the renderer alike.  That module
imports every material's; it hands its batch kernels to :data:`BATCHES` when it is imported (the package imports
it), so that this module, which the materials import, imports none of them.
"""

from __future__ import annotations

import math

import numpy as np

from .._worksharing import read_only
from ..errors import ParameterError, numeric_array

__all__ = ["BSDF", "PARAM_SIZE", "TEXTURED_PARAM_SIZE", "rgb_param"]

#: Length of every material's parameter block.
PARAM_SIZE = 80
#: Length of the leading part of a textured material's block that a camera sample keeps its own copy of.
TEXTURED_PARAM_SIZE = 8

#: (eval_batch, pdf_batch, sample_batch) of :mod:`lightprobe.bsdfs.dispatch`, set when it is imported
BATCHES: list = []


def rgb_param(value, name: str, *, upper: float | None = None) -> np.ndarray:
    """A scalar or RGB triple as a float64 (3,) array, checked finite, >= 0 and <= ``upper``."""
    arr = numeric_array(value, name).reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    # checked as Python floats (a scene of 100,000 emitters checks as many radiances: NumPy's reductions on three
    # numbers cost several microseconds each)
    values = arr.tolist()
    if arr.size != 3 or not all(math.isfinite(x) for x in values):
        raise ParameterError(f"{name} must be a finite number or an RGB triple, got {value!r}")
    if min(values) < 0.0 or (upper is not None and max(values) > upper):
        bound = f"[0, {upper}]" if upper is not None else ">= 0"
        raise ParameterError(f"{name} must be in {bound}, got {value!r}")
    return arr


def _directions(v, name: str, n: int | None = None) -> np.ndarray:
    arr = np.asarray(v, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == 3 and n is not None:
        arr = np.broadcast_to(arr, (n, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ParameterError(f"{name} must be an (N, 3) array of directions, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise ParameterError(f"{name} has {arr.shape[0]} rows, expected {n}")
    return read_only(np.ascontiguousarray(arr))  # one signature of the batch kernels, whatever the caller passed


class BSDF:
    """Base class: subclasses set ``kind`` and fill ``params`` (length :data:`PARAM_SIZE`).  A material that can
    be textured names the uses it takes in ``texture_uses`` and keeps its :class:`MaterialTextures` (or None) in
    ``textures``; its block then fits in :data:`TEXTURED_PARAM_SIZE`, the width of a camera sample's own block."""

    kind: int = -1
    texture_uses: tuple[str, ...] = ()

    def __init__(self) -> None:
        self.params = np.zeros(PARAM_SIZE)
        self.textures = None

    def check_textures(self, textures):
        """``textures`` checked against what this material takes (None or a MaterialTextures)."""
        from ..textures.material_textures import MaterialTextures

        if textures is None:
            return None
        name = type(self).__name__
        if not isinstance(textures, MaterialTextures):
            raise ParameterError(f"{name}: textures must be a MaterialTextures, got {type(textures).__name__}")
        extra = [use for use in textures.used() if use not in self.texture_uses]
        if extra:
            takes = ", ".join(self.texture_uses) or "none"
            raise ParameterError(f"{name}: takes no {', '.join(extra)} texture (it takes: {takes})")
        return textures if textures.used() or textures.masked else None

    def eval(self, wo, wi) -> np.ndarray:
        """BRDF value f(wo, wi), RGB (N, 3), without the cosine factor."""
        eval_batch = BATCHES[0]
        wi = _directions(wi, "wi")
        return eval_batch(self.kind, self.params, _directions(wo, "wo", wi.shape[0]), wi)

    def pdf(self, wo, wi) -> np.ndarray:
        """Density per steradian (N,) with which :meth:`sample` produces ``wi`` given ``wo``."""
        pdf_batch = BATCHES[1]
        wi = _directions(wi, "wi")
        return pdf_batch(self.kind, self.params, _directions(wo, "wo", wi.shape[0]), wi)

    def sample(self, wo, u) -> tuple[np.ndarray, np.ndarray]:
        """Sample incident directions: returns ``(wi (N, 3), pdf (N,))``."""
        wi, pdf, _ = self.sample_weight(wo, u)
        return wi, pdf

    def sample_weight(self, wo, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Like :meth:`sample`, plus the sample weight f(wo, wi) cos(theta_i) / pdf (N, 3), 0 when invalid."""
        sample_batch = BATCHES[2]
        uu = np.asarray(u, dtype=np.float64)
        if uu.ndim != 2 or uu.shape[1] != 3:
            raise ParameterError(f"u must be an (N, 3) array, got shape {uu.shape}")
        return sample_batch(
            self.kind, self.params, _directions(wo, "wo", uu.shape[0]), read_only(np.ascontiguousarray(uu))
        )
