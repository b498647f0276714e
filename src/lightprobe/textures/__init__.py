"""Image textures and the materials' use of them (glTF 2.0's base colour, metallic-roughness and normal maps)."""

from .image_texture import CLAMP, MIRRORED_REPEAT, REPEAT, ImageTexture, TextureTable, pack_textures
from .material_textures import MaterialTextures
from .tangents import generate_tangents

__all__ = [
    "CLAMP",
    "MIRRORED_REPEAT",
    "REPEAT",
    "ImageTexture",
    "MaterialTextures",
    "TextureTable",
    "generate_tangents",
    "pack_textures",
]
