"""Image textures: texels, wrap modes, filtering, and the lookup the render kernels make.

A texture is an (H, W, 4) image, row 0 at the top, addressed by glTF's texture coordinates: (u, v) = (0, 0) is the
top-left corner of the first texel, u runs along a row and v down the rows, and texel (i, j) has its centre at
((i + 1/2) / W, (j + 1/2) / H).  Coordinates outside [0, 1] are wrapped per axis (glTF's sampler ``wrapS`` /
``wrapT``): ``repeat``, ``mirrored_repeat`` or ``clamp`` (to the edge).  The filter is ``linear`` (bilinear over the
four nearest texel centres, glTF's default) or ``nearest``; there is no MIP-mapping, so a texture seen from far away
aliases within a pixel and the pixel's samples average it (each camera sample looks up its own point).

Storage (the memory the kernels hold; ``nbytes``): an 8-bit image keeps its bytes (4 per texel), decoded per lookup
through a 256-entry table (sRGB or linear), so a 4096 x 4096 texture costs 64 MiB; anything else (16-bit, float)
is float32, 16 bytes per texel (256 MiB at 4096 x 4096).  Grey images are expanded to RGB and a missing alpha is 1.
Decoding is per use, not per image: a base colour or emissive texture holds sRGB values (IEC 61966-2-1), decoded to
linear before filtering; metallic-roughness and normal textures are linear.

All textures of a scene are packed into one table (:func:`pack_textures`) that the kernels read with
:func:`texture_lookup`, each texture's texels in 4 x 4 tiles (pbrt's blocked arrays): an 8-bit tile is 64 bytes, one
cache line, so a bilinear lookup's 2 x 2 texels lie in one line unless they straddle a tile's edge (9 times in 16
they do not), where rows of a 4096-texel image put them 16 KiB apart (decisions.md 85).
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np

from .._numba import jit, jit_alloc, jit_inline
from ..color import srgb_to_linear
from ..errors import ImageError, ParameterError, library_message, library_output_held

__all__ = [
    "CLAMP",
    "MIRRORED_REPEAT",
    "REPEAT",
    "ImageTexture",
    "TextureTable",
    "pack_textures",
    "texture_lookup",
    "triangle_means",
]

REPEAT, MIRRORED_REPEAT, CLAMP = 0, 1, 2
WRAPS = {"repeat": REPEAT, "mirrored_repeat": MIRRORED_REPEAT, "clamp": CLAMP}
LINEAR, NEAREST = 0, 1
FILTERS = {"linear": LINEAR, "nearest": NEAREST}
# columns of the texture table
_OFFSET, _WIDTH, _HEIGHT, _WRAP_S, _WRAP_T, _FILTER, _FLOAT = range(7)
TABLE_WIDTH = 7

# 8-bit code value -> linear value, by the sRGB curve (IEC 61966-2-1) and plainly (/ 255)
LINEAR_TABLE = np.arange(256, dtype=np.float64) / 255.0
SRGB_TABLE = srgb_to_linear(LINEAR_TABLE)


class ImageTexture:
    """An image texture: ``pixels`` (H, W) or (H, W, C) with C in 1..4, uint8 (kept as bytes) or any real dtype
    (kept as float32); ``wrap`` one mode or a (u, v) pair of ``repeat`` / ``mirrored_repeat`` / ``clamp``;
    ``filter`` ``linear`` or ``nearest``.  See the module docstring."""

    def __init__(self, pixels, *, wrap="repeat", filter: str = "linear", name: str = "<texture>"):
        self.name = str(name)
        a = np.asarray(pixels)
        if a.ndim == 2:
            a = a[:, :, None]
        if a.ndim != 3 or not 1 <= a.shape[2] <= 4 or a.shape[0] < 1 or a.shape[1] < 1:
            raise ParameterError(f"{self.name}: a texture must be an (H, W) or (H, W, 1..4) image, got shape {a.shape}")
        if a.dtype == np.uint8:
            full, one = np.empty((*a.shape[:2], 4), np.uint8), 255
        elif np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating) or a.dtype == np.bool_:
            a = a.astype(np.float32)
            if not np.all(np.isfinite(a)):
                raise ParameterError(f"{self.name}: the texture holds NaN or infinite values")
            full, one = np.empty((*a.shape[:2], 4), np.float32), 1.0
        else:
            raise ParameterError(f"{self.name}: texture pixels must be numbers, got dtype {a.dtype}")
        channels = a.shape[2]
        colour = a[:, :, :3] if channels >= 3 else np.repeat(a[:, :, :1], 3, axis=2)
        full[:, :, :3] = colour
        if channels == 4:
            full[:, :, 3] = a[:, :, 3]
        elif channels == 2:  # grey and alpha
            full[:, :, 3] = a[:, :, 1]
        else:
            full[:, :, 3] = one
        self.pixels = np.ascontiguousarray(full)
        pair = (wrap, wrap) if isinstance(wrap, str) else tuple(wrap)
        if len(pair) != 2 or any(w not in WRAPS for w in pair):
            raise ParameterError(f"{self.name}: wrap must be one of {', '.join(WRAPS)} or a (u, v) pair, got {wrap!r}")
        self.wrap = pair
        if filter not in FILTERS:
            raise ParameterError(f"{self.name}: filter must be 'linear' or 'nearest', got {filter!r}")
        self.filter = filter

    @property
    def height(self) -> int:
        return self.pixels.shape[0]

    @property
    def width(self) -> int:
        return self.pixels.shape[1]

    @property
    def is_float(self) -> bool:
        return self.pixels.dtype == np.float32

    @property
    def nbytes(self) -> int:
        """Bytes the render kernels hold for this texture."""
        return self.pixels.nbytes

    @classmethod
    def read(cls, path, *, wrap="repeat", filter: str = "linear", name: str | None = None) -> ImageTexture:
        """Read an image file (PNG, JPEG, EXR, TIFF ... through OpenImageIO); 8-bit files keep their bytes."""
        p = Path(path)
        label = name or str(p)
        if not p.exists():
            raise ImageError(f"{label}: no such file")
        return cls(_decode(p, label), wrap=wrap, filter=filter, name=label)

    @classmethod
    def from_bytes(cls, data: bytes, *, suffix: str, wrap="repeat", filter: str = "linear", name: str) -> ImageTexture:
        """Decode an encoded image held in memory (a GLB's image, a data URI); ``suffix`` names its format."""
        with tempfile.TemporaryDirectory(prefix="lightprobe-texture-") as tmp:
            file = Path(tmp) / f"image{suffix}"
            file.write_bytes(data)
            pixels = _decode(file, name)
        return cls(pixels, wrap=wrap, filter=filter, name=name)

    def mean_rgb(self, *, srgb: bool) -> np.ndarray:
        """The mean of the texels' colour, decoded to linear (sRGB or plain)."""
        if self.is_float:
            rgb = self.pixels[:, :, :3].astype(np.float64)
            if srgb:
                rgb = srgb_to_linear(rgb)
        else:
            rgb = (SRGB_TABLE if srgb else LINEAR_TABLE)[self.pixels[:, :, :3]]
        return rgb.reshape(-1, 3).mean(axis=0)

    def __repr__(self) -> str:
        kind = "float32" if self.is_float else "8-bit"
        return f"ImageTexture({self.name!r}, {self.width}x{self.height} {kind}, wrap={self.wrap}, filter={self.filter})"


def _decode(path: Path, label: str) -> np.ndarray:
    """An image file's pixels: uint8 for 8-bit files, float32 otherwise (16-bit: code / 65535)."""
    import OpenImageIO as oiio

    with library_output_held() as succeeded:  # libpng's own 'libpng error' lines: the error below says it
        inp = oiio.ImageInput.open(os.fspath(path))
        if inp is None:
            raise ImageError(f"{label}: cannot read image ({library_message(oiio.geterror(), 'unknown format')})")
        try:
            stored = str(inp.spec().format)
            eight_bit = stored in ("uint8", "int8")
            pixels = inp.read_image(oiio.UINT8 if eight_bit else oiio.FLOAT)
            err = inp.geterror()
        finally:
            inp.close()
        if pixels is None or not isinstance(pixels, np.ndarray) or pixels.size == 0:
            raise ImageError(f"{label}: cannot read image data ({library_message(err, 'corrupt or truncated file')})")
        succeeded.append(True)
    if not eight_bit and not np.all(np.isfinite(pixels)):
        raise ImageError(f"{label}: the image holds NaN or infinite values")
    return pixels


TILE = 4  # texels along a side of a storage tile (``_tiled_row`` computes with shifts for 4)


class TextureTable:
    """Every texture of a scene in the kernels' layout: ``table`` (T, 7) int64 rows of (offset, width, height,
    wrap u, wrap v, filter, float), ``bytes`` (N, 4) uint8 texels of the 8-bit textures and ``floats`` (M, 4)
    float32 of the others, each texture's rows at its offset, in 4 x 4 tiles (row-major tiles of row-major texels;
    the image padded to whole tiles)."""

    def __init__(self, table: np.ndarray, texel_bytes: np.ndarray, texel_floats: np.ndarray):
        self.table, self.bytes, self.floats = table, texel_bytes, texel_floats

    @property
    def nbytes(self) -> int:
        return self.table.nbytes + self.bytes.nbytes + self.floats.nbytes


def pack_textures(textures: list[ImageTexture]) -> TextureTable:
    """Pack ``textures`` (in order: texture i is row i of the table)."""
    table = np.zeros((len(textures), TABLE_WIDTH), np.int64)
    byte_parts, float_parts = [], []
    n_bytes = n_floats = 0
    for i, tex in enumerate(textures):
        texels = _tiled(tex.pixels)
        if tex.is_float:
            table[i, _OFFSET], n_floats = n_floats, n_floats + texels.shape[0]
            float_parts.append(texels)
        else:
            table[i, _OFFSET], n_bytes = n_bytes, n_bytes + texels.shape[0]
            byte_parts.append(texels)
        table[i, _WIDTH], table[i, _HEIGHT] = tex.width, tex.height
        table[i, _WRAP_S], table[i, _WRAP_T] = WRAPS[tex.wrap[0]], WRAPS[tex.wrap[1]]
        table[i, _FILTER], table[i, _FLOAT] = FILTERS[tex.filter], int(tex.is_float)
    texel_bytes = np.ascontiguousarray(np.concatenate(byte_parts)) if byte_parts else np.zeros((0, 4), np.uint8)
    texel_floats = np.ascontiguousarray(np.concatenate(float_parts)) if float_parts else np.zeros((0, 4), np.float32)
    return TextureTable(table, texel_bytes, texel_floats)


def _tiled(pixels: np.ndarray) -> np.ndarray:
    """(H, W, 4) texels as rows of 4 x 4 tiles, the tiles row by row, each tile's texels row by row."""
    h, w = pixels.shape[:2]
    ty, tx = -(-h // TILE), -(-w // TILE)
    padded = np.zeros((ty * TILE, tx * TILE, 4), pixels.dtype)
    padded[:h, :w] = pixels
    return np.ascontiguousarray(padded.reshape(ty, TILE, tx, TILE, 4).transpose(0, 2, 1, 3, 4).reshape(-1, 4))


@jit_inline
def _tiled_row(width, i, j):
    """Texel (i, j)'s row within its texture's tiled storage (``_tiled``; i, j >= 0, shifts for TILE = 4)."""
    tiles_across = (width + 3) >> 2
    return ((((j >> 2) * tiles_across + (i >> 2)) << 4) | ((j & 3) << 2)) | (i & 3)


@jit_inline
def _wrapped_coordinate(x, mode):
    """A texture coordinate brought into [0, 1] (repeat), [0, 2) (mirrored repeat, folded by the caller per texel)
    or [0, 1] (clamp), so that scaling it by the size cannot overflow an integer."""
    # np.floor, not math.floor: Numba's math.floor returns an int64, which overflows beyond 2^63
    if mode == REPEAT:
        return x - np.floor(x)
    if mode == MIRRORED_REPEAT:
        return x - 2.0 * np.floor(0.5 * x)
    return min(max(x, 0.0), 1.0)


@jit_inline
def _wrapped_index(i, n, mode):
    if mode == REPEAT:
        return i % n
    if mode == MIRRORED_REPEAT:
        j = i % (2 * n)
        return j if j < n else 2 * n - 1 - j
    return min(max(i, 0), n - 1)


@jit_inline
def _srgb_decode(x):
    x = min(max(x, 0.0), 1.0)
    return x / 12.92 if x <= 0.04045 else ((x + 0.055) / 1.055) ** 2.4


@jit
def _texel(table, texel_bytes, texel_floats, t, i, j, srgb):
    """Texel (i, j) of texture t (indices already wrapped) as linear RGBA.  Called, not inlined: a lookup reads
    up to four, and each inlined copy was compiled again (decisions.md 130)."""
    row = table[t, _OFFSET] + _tiled_row(table[t, _WIDTH], i, j)
    if table[t, _FLOAT] == 1:
        x = texel_floats[row]
        r, g, b = float(x[0]), float(x[1]), float(x[2])
        if srgb:
            r, g, b = _srgb_decode(r), _srgb_decode(g), _srgb_decode(b)
        return r, g, b, float(x[3])
    x = texel_bytes[row]
    if srgb:
        return SRGB_TABLE[x[0]], SRGB_TABLE[x[1]], SRGB_TABLE[x[2]], LINEAR_TABLE[x[3]]
    return LINEAR_TABLE[x[0]], LINEAR_TABLE[x[1]], LINEAR_TABLE[x[2]], LINEAR_TABLE[x[3]]


@jit
def texture_lookup(table, texel_bytes, texel_floats, t, u, v, srgb):
    """Texture t at (u, v), filtered and wrapped as its table row says: linear (r, g, b, a); sRGB-decoded colour
    (before filtering, as glTF asks) when ``srgb``.  Non-finite coordinates read texel (0, 0)."""
    w, h = table[t, _WIDTH], table[t, _HEIGHT]
    ws, wt = table[t, _WRAP_S], table[t, _WRAP_T]
    if not (math.isfinite(u) and math.isfinite(v)):
        u = v = 0.0
    x = _wrapped_coordinate(u, ws) * w
    y = _wrapped_coordinate(v, wt) * h
    if table[t, _FILTER] == NEAREST:
        i = _wrapped_index(int(np.floor(x)), w, ws)
        j = _wrapped_index(int(np.floor(y)), h, wt)
        return _texel(table, texel_bytes, texel_floats, t, i, j, srgb)
    x -= 0.5
    y -= 0.5
    fx, fy = np.floor(x), np.floor(y)
    ax, ay = x - fx, y - fy
    i0, j0 = int(fx), int(fy)
    i1, j1 = _wrapped_index(i0 + 1, w, ws), _wrapped_index(j0 + 1, h, wt)
    i0, j0 = _wrapped_index(i0, w, ws), _wrapped_index(j0, h, wt)
    c00 = _texel(table, texel_bytes, texel_floats, t, i0, j0, srgb)
    c10 = _texel(table, texel_bytes, texel_floats, t, i1, j0, srgb)
    c01 = _texel(table, texel_bytes, texel_floats, t, i0, j1, srgb)
    c11 = _texel(table, texel_bytes, texel_floats, t, i1, j1, srgb)
    w00, w10, w01, w11 = (1.0 - ax) * (1.0 - ay), ax * (1.0 - ay), (1.0 - ax) * ay, ax * ay
    return (
        w00 * c00[0] + w10 * c10[0] + w01 * c01[0] + w11 * c11[0],
        w00 * c00[1] + w10 * c10[1] + w01 * c01[1] + w11 * c11[1],
        w00 * c00[2] + w10 * c10[2] + w01 * c01[2] + w11 * c11[2],
        w00 * c00[3] + w10 * c10[3] + w01 * c01[3] + w11 * c11[3],
    )


def triangle_means(texture: ImageTexture, uv_triangles: np.ndarray, *, srgb: bool) -> np.ndarray:
    """The mean colour (F, 3) of ``texture`` over each triangle of texture coordinates (F, 3, 2): the average of the
    filtered lookups at the centroids of the triangle's 16 equal sub-triangles (exact where the texture is linear
    across the triangle)."""
    n = 4
    up = [((i + 1 / 3) / n, (j + 1 / 3) / n) for i in range(n) for j in range(n - i)]
    down = [((i + 2 / 3) / n, (j + 2 / 3) / n) for i in range(n - 1) for j in range(n - 1 - i)]
    bary = np.array(up + down)  # (16, 2): weights of vertices 1 and 2
    t = np.asarray(uv_triangles, dtype=np.float64)
    points = (
        t[:, None, 0] * (1.0 - bary[None, :, 0:1] - bary[None, :, 1:2])
        + t[:, None, 1] * bary[None, :, 0:1]
        + t[:, None, 2] * bary[None, :, 1:2]
    )  # (F, 16, 2)
    values = lookup_batch(pack_textures([texture]), 0, points.reshape(-1, 2), srgb=srgb)[:, :3]
    return values.reshape(t.shape[0], bary.shape[0], 3).mean(axis=1)


def lookup_batch(table: TextureTable, t: int, uv: np.ndarray, *, srgb: bool) -> np.ndarray:
    """:func:`texture_lookup` at each row of ``uv`` (N, 2): (N, 4) linear RGBA (tests and tools)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    return _lookup_batch(table.table, table.bytes, table.floats, int(t), uv, bool(srgb))


@jit_alloc
def _lookup_batch(table, texel_bytes, texel_floats, t, uv, srgb):
    out = np.empty((uv.shape[0], 4))
    for n in range(uv.shape[0]):
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = texture_lookup(
            table, texel_bytes, texel_floats, t, uv[n, 0], uv[n, 1], srgb
        )
    return out
