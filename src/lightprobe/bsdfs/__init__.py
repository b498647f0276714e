"""BSDFs in the local shading frame (normal +z, ``wo`` toward the viewer, ``wi`` toward the light)."""

from . import dispatch  # noqa: F401 - gives the BSDF classes their batch kernels (base.BATCHES)
from .base import BSDF
from .conductor import GGXConductor
from .lambert import Lambert
from .metallic_roughness import MetallicRoughness
from .phong import Phong
from .plastic import RoughPlastic

__all__ = ["BSDF", "GGXConductor", "Lambert", "MetallicRoughness", "Phong", "RoughPlastic"]
