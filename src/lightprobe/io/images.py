"""Reading and writing images: OpenEXR, Radiance .hdr, PFM (linear float) and PNG (tone mapped, sRGB).

EXR, .hdr and PNG go through OpenImageIO; PFM is read and written here (OpenImageIO 3.2 reads PFM upside
down: its rows are stored bottom to top).  Linear images are float32 arrays of shape (height, width, channels), row 0
at the top.  PNG output applies an exposure (in stops), clips to [0, 1] and encodes with the sRGB transfer curve;
it never sees NaN or infinity (they are written as 0 and reported).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import ImageError, ParameterError

__all__ = ["LINEAR_FORMATS", "linear_to_srgb", "read_image", "srgb_to_linear", "write_image", "write_png"]

LINEAR_FORMATS = (".exr", ".hdr", ".pfm")
_DISPLAY_FORMATS = (".png", ".jpg", ".jpeg")


def _oiio():
    import OpenImageIO as oiio  # imported lazily: it is only needed for file I/O

    return oiio


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image as float32 (H, W, C).  Raises :class:`ImageError` naming the file if it cannot."""
    p = Path(path)
    if not p.exists():
        raise ImageError(f"{p}: no such file")
    if p.is_dir():
        raise ImageError(f"{p}: is a directory, not an image")
    if p.suffix.lower() == ".pfm":
        return _read_pfm(p)
    oiio = _oiio()
    inp = oiio.ImageInput.open(str(p))
    if inp is None:
        msg = oiio.geterror().strip().splitlines()
        raise ImageError(f"{p}: cannot read image ({msg[-1] if msg else 'unknown format'})")
    try:
        pixels = inp.read_image(oiio.FLOAT)
        err = inp.geterror()
    finally:
        inp.close()
    if pixels is None or not isinstance(pixels, np.ndarray) or pixels.size == 0:
        raise ImageError(f"{p}: cannot read image data ({err.strip() or 'corrupt or truncated file'})")
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return np.ascontiguousarray(pixels, dtype=np.float32)


def write_image(
    path: str | os.PathLike,
    pixels: np.ndarray,
    *,
    channel_names: Sequence[str] | None = None,
    half: bool = False,
) -> Path:
    """Write a linear float image (.exr, .hdr, .pfm) or, for .png/.jpg, a tone-mapped one via :func:`write_png`.

    ``channel_names`` names the channels of an EXR (default R, G, B[, A]); ``half`` stores EXR as float16.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext in _DISPLAY_FORMATS:
        return write_png(p, pixels)
    if ext not in LINEAR_FORMATS:
        raise ImageError(f"{p}: unsupported output format {ext or '(none)'}; use .exr, .hdr, .pfm or .png")
    data = np.asarray(pixels, dtype=np.float32)
    if data.ndim == 2:
        data = data[:, :, None]
    channels = data.shape[2]
    if ext in (".hdr", ".pfm") and channels != 3:
        data = data[:, :, :3] if channels > 3 else np.repeat(data[:, :, :1], 3, axis=2)
        channels = 3
    if ext == ".pfm":
        return _write_pfm(p, data)
    oiio = _oiio()
    spec = oiio.ImageSpec(data.shape[1], data.shape[0], channels, oiio.HALF if half else oiio.FLOAT)
    if channel_names is not None and ext == ".exr":
        if len(channel_names) != channels:
            raise ParameterError(f"channel_names has {len(channel_names)} names for {channels} channels")
        spec.channelnames = tuple(channel_names)
    if ext == ".exr":
        spec.attribute("compression", "zip")
    p.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(p))
    if out is None or not out.open(str(p), spec):
        raise ImageError(f"{p}: cannot write ({oiio.geterror().strip() or 'open failed'})")
    try:
        ok = out.write_image(np.ascontiguousarray(data))
        err = out.geterror()
    finally:
        out.close()
    if not ok:
        raise ImageError(f"{p}: cannot write ({err.strip()})")
    return p


def _read_pfm(p: Path) -> np.ndarray:
    """Portable float map: 'PF' (RGB) or 'Pf' (grey), width height, scale (< 0: little endian), rows bottom-up."""
    try:
        with open(p, "rb") as f:
            header = [f.readline().strip() for _ in range(3)]
            kind, size, scale = header
            channels = {b"PF": 3, b"Pf": 1}[kind]
            width, height = (int(t) for t in size.split())
            dtype = "<f4" if float(scale) < 0 else ">f4"
            data = np.fromfile(f, dtype=dtype, count=width * height * channels)
    except (OSError, ValueError, KeyError) as exc:
        raise ImageError(f"{p}: not a valid PFM file ({exc})") from None
    if width <= 0 or height <= 0 or data.size != width * height * channels:
        raise ImageError(f"{p}: truncated PFM file ({data.size} of {width * height * channels} values)")
    return np.ascontiguousarray(data.reshape(height, width, channels)[::-1], dtype=np.float32)


def _write_pfm(p: Path, data: np.ndarray) -> Path:
    p.parent.mkdir(parents=True, exist_ok=True)
    height, width = data.shape[:2]
    try:
        with open(p, "wb") as f:
            f.write(f"PF\n{width} {height}\n-1.0\n".encode())
            f.write(np.ascontiguousarray(data[::-1, :, :3], dtype="<f4").tobytes())
    except OSError as exc:
        raise ImageError(f"{p}: cannot write ({exc.strerror})") from None
    return p


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve (IEC 61966-2-1) on values clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def write_png(path: str | os.PathLike, linear_rgb: np.ndarray, *, exposure: float = 0.0) -> Path:
    """Tone map linear RGB (multiply by 2^exposure, clip, sRGB encode) and write an 8-bit PNG/JPEG."""
    if not math.isfinite(exposure):
        raise ParameterError(f"exposure must be finite, got {exposure}")
    data = np.asarray(linear_rgb, dtype=np.float64)
    if data.ndim == 2:
        data = data[:, :, None]
    data = data[:, :, :3] if data.shape[2] >= 3 else np.repeat(data[:, :, :1], 3, axis=2)
    data = np.where(np.isfinite(data), data, 0.0) * 2.0**exposure
    encoded = np.round(linear_to_srgb(data) * 255.0).astype(np.uint8)
    p = Path(path)
    oiio = _oiio()
    spec = oiio.ImageSpec(encoded.shape[1], encoded.shape[0], 3, oiio.UINT8)
    p.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(p))
    if out is None or not out.open(str(p), spec):
        raise ImageError(f"{p}: cannot write ({oiio.geterror().strip() or 'open failed'})")
    try:
        ok = out.write_image(np.ascontiguousarray(encoded))
    finally:
        out.close()
    if not ok:
        raise ImageError(f"{p}: cannot write PNG")
    return p
