"""Reading and writing images: OpenEXR, Radiance .hdr, PFM (linear float) and PNG (tone mapped, sRGB).

EXR, .hdr and PNG go through OpenImageIO; PFM is read and written here (OpenImageIO 3.2 reads PFM upside
down: its rows are stored bottom to top).  Linear images are float32 arrays of shape (height, width, channels), row 0
at the top.  PNG output applies an exposure (in stops), clips to [0, 1] and encodes with the sRGB transfer curve;
it never sees NaN or infinity (they are written as 0 and reported).
"""

from __future__ import annotations

import contextlib
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .color import linear_to_srgb, srgb_to_linear
from .errors import ImageError, ParameterError, library_message, library_output_held, warn_once

__all__ = [
    "LINEAR_FORMATS",
    "linear_to_srgb",
    "read_image",
    "read_radiance",
    "srgb_to_linear",
    "write_image",
    "write_png",
]

LINEAR_FORMATS = (".exr", ".hdr", ".pfm")
_DISPLAY_FORMATS = (".png", ".jpg", ".jpeg")


def _oiio():
    import OpenImageIO as oiio  # imported lazily: it is only needed for file I/O

    return oiio


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image's stored values as float32 (H, W, C), without colour conversion (an 8-bit PNG gives its
    code values / 255).  Raises :class:`ImageError` naming the file if it cannot.  For radiance, use
    :func:`read_radiance`."""
    return _read(Path(path))[0]


def read_radiance(path: str | os.PathLike) -> np.ndarray:
    """Read an image as *linear* float32 (H, W, C) radiance.

    Linear formats (EXR, HDR, PFM, float TIFF) are returned as stored.  A display-encoded image (an 8- or 16-bit
    PNG/JPEG/TIFF, or any file OpenImageIO tags as sRGB or gamma-encoded) is decoded with the sRGB transfer
    function (IEC 61966-2-1; not a 2.2 power), or with the power its tag names (``Gamma1.8``), and a warning says
    that such a file cannot hold the dynamic range of the sun, so the lighting is only an approximation.
    """
    p = Path(path)
    pixels, encoding = _read(p)
    if encoding == "linear":
        return pixels
    if encoding == "srgb":
        decoded, how = srgb_to_linear(pixels), "the sRGB curve"
    else:
        gamma = float(encoding)
        decoded, how = np.power(np.clip(pixels, 0.0, None), gamma), f"a {gamma:g} power"
    warn_once(
        f"{p}: a display-encoded (low dynamic range) image, decoded to linear radiance with {how}; it cannot "
        "hold the range of the sun or bright lights (use an .exr or .hdr map for real lighting)"
    )
    return np.ascontiguousarray(decoded, dtype=np.float32)


def _encoding(colorspace: str, integer_data: bool) -> str:
    """'linear', 'srgb', or a gamma as text, from OpenImageIO's ``oiio:ColorSpace`` tag (names of OIIO 2.x
    and 3.x: 'sRGB', 'srgb_rec709_scene', 'Gamma2.2', 'g22_rec709_scene', 'linear', 'lin_rec709_scene')."""
    name = colorspace.strip().lower()
    if "srgb" in name:
        return "srgb"
    match = re.fullmatch(r"(?:gamma(?:corrected)?)\s*([0-9.]+)|g(\d)(\d)_.*", name)
    if match:
        return match.group(1) if match.group(1) else f"{match.group(2)}.{match.group(3)}"
    if name.startswith("lin") or name in ("raw", "acescg", "aces2065-1", "scene_linear"):
        return "linear"
    # untagged: integer pixels are display-encoded in practice (an 8-bit TIFF), floats are linear
    return "srgb" if integer_data else "linear"


def _read(p: Path) -> tuple[np.ndarray, str]:
    """Pixels as stored (float32 H x W x C) and their encoding (see :func:`_encoding`)."""
    if not p.exists():
        raise ImageError(f"{p}: no such file")
    if p.is_dir():
        raise ImageError(f"{p}: is a directory, not an image")
    if p.suffix.lower() == ".pfm":
        return _read_pfm(p), "linear"
    oiio = _oiio()
    with library_output_held() as succeeded:
        inp = oiio.ImageInput.open(str(p))
        if inp is None:
            raise ImageError(f"{p}: cannot read image ({library_message(oiio.geterror(), 'unknown format')})")
        try:
            spec = inp.spec()
            stored = str(spec.format)
            encoding = _encoding(str(spec.getattribute("oiio:ColorSpace") or ""), stored.startswith(("uint", "int")))
            pixels = inp.read_image(oiio.FLOAT)
            err = inp.geterror()
        finally:
            inp.close()
        if pixels is None or not isinstance(pixels, np.ndarray) or pixels.size == 0:
            raise ImageError(f"{p}: cannot read image data ({library_message(err, 'corrupt or truncated file')})")
        succeeded.append(True)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return np.ascontiguousarray(pixels, dtype=np.float32), encoding


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
    _write_oiio(p, spec, np.ascontiguousarray(data))
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
    height, width = data.shape[:2]
    with _replaced_atomically(p) as tmp:
        with open(tmp, "wb") as f:
            f.write(f"PF\n{width} {height}\n-1.0\n".encode())
            f.write(np.ascontiguousarray(data[::-1, :, :3], dtype="<f4").tobytes())
    return p


@contextlib.contextmanager
def _replaced_atomically(p: Path):
    """Yield a temporary path beside ``p`` (same extension, so writers pick the same format); on success it
    replaces ``p`` in one rename, on failure it is removed: a failed write (a full disk) never leaves a truncated
    file or destroys an older one.  ``OSError`` becomes an :class:`ImageError` naming ``p``."""
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ImageError(f"{p}: cannot write ({exc.strerror or exc})") from None
    tmp = p.with_name(f".{p.stem}.partial-{os.getpid()}{p.suffix}")
    try:
        yield tmp
        os.replace(tmp, p)
    except OSError as exc:
        raise ImageError(f"{p}: cannot write ({exc.strerror or exc})") from None
    finally:
        tmp.unlink(missing_ok=True)


def _write_oiio(p: Path, spec, pixels: np.ndarray) -> None:
    oiio = _oiio()
    with _replaced_atomically(p) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise ImageError(f"{p}: cannot write ({library_message(oiio.geterror(), 'open failed')})")
        try:
            ok = out.write_image(pixels)
            err = out.geterror()
        finally:
            out.close()
        if not ok:
            raise ImageError(f"{p}: cannot write ({library_message(err, 'write failed')})")


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
    _write_oiio(p, oiio.ImageSpec(encoded.shape[1], encoded.shape[0], 3, oiio.UINT8), np.ascontiguousarray(encoded))
    return p
