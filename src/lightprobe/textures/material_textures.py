"""Which textures a material reads, and what each one does (glTF 2.0's metallic-roughness material, section 3.9).

- ``base_color`` (sRGB): multiplies the material's base colour (a Lambert's albedo, a metallic-roughness material's
  ``base_color``), channel by channel; its alpha is the surface's coverage, unused (every material is opaque);
- ``metallic_roughness`` (linear): its blue channel multiplies ``metallic`` and its green channel ``roughness``
  (metallic-roughness materials only);
- ``normal`` (linear, tangent space): the shading normal becomes normalize((2 c - 1) (scale, scale, 1)) in the
  frame of the mesh's tangent, bitangent and normal (see ``integrators/textured_hits.py``).

``alpha_mode = "mask"`` cuts the surface out where its coverage, ``alpha_factor`` x the base-colour texture's
alpha, is below ``alpha_cutoff`` (glTF's ``MASK``; ``geometry/alpha_mask.py``), for camera, BSDF and shadow rays
alike; ``"opaque"`` ignores alpha.  (glTF's ``BLEND`` is rendered as ``MASK`` at 0.5 by the glTF reader, with a
warning: the renderer has no partial transparency.)

Textures need a triangle mesh with texture coordinates (``TriangleMesh.uvs``); a normal map also uses its tangents,
generated when the mesh has none (``textures/tangents.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import ParameterError
from .image_texture import ImageTexture

__all__ = ["MaterialTextures"]

#: columns of the scene's material-texture table: the texture row of each use, -1 for none
BASE_COLOR, METALLIC_ROUGHNESS, NORMAL = 0, 1, 2
USES = ("base_color", "metallic_roughness", "normal")


@dataclass(frozen=True)
class MaterialTextures:
    """The textures of one material (any may be None).  See the module docstring."""

    base_color: ImageTexture | None = None
    metallic_roughness: ImageTexture | None = None
    normal: ImageTexture | None = None
    normal_scale: float = 1.0
    alpha_mode: str = "opaque"
    alpha_cutoff: float = 0.5
    alpha_factor: float = 1.0

    def __post_init__(self):
        for use in USES:
            value = getattr(self, use)
            if value is not None and not isinstance(value, ImageTexture):
                raise ParameterError(f"textures: {use} must be an ImageTexture, got {type(value).__name__}")
        if not math.isfinite(float(self.normal_scale)):
            raise ParameterError(f"textures: normal_scale must be finite, got {self.normal_scale!r}")
        if self.alpha_mode not in ("opaque", "mask"):
            raise ParameterError(f"textures: alpha_mode must be 'opaque' or 'mask', got {self.alpha_mode!r}")
        for name in ("alpha_cutoff", "alpha_factor"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise ParameterError(f"textures: {name} must be in [0, 1], got {getattr(self, name)!r}")

    @property
    def masked(self) -> bool:
        return self.alpha_mode == "mask"

    def used(self) -> dict[str, ImageTexture]:
        """The textures present, by use."""
        return {use: getattr(self, use) for use in USES if getattr(self, use) is not None}
