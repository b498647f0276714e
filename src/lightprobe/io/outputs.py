"""Writing renders: linear EXR/HDR/PFM (optionally with per-pixel variance), tone-mapped PNG, JSON sidecar.

The sidecar (``<output>.json``) records the settings, timings and throughput (seconds, samples/s, rays/s), the
samples actually taken per pixel, and whether the render was interrupted or stopped by its time limit.
"""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import ImageError
from .images import LINEAR_FORMATS, write_image, write_png

__all__ = ["check_output", "write_render"]

VARIANCE_CHANNELS = ("R", "G", "B", "variance.R", "variance.G", "variance.B")


def _json_safe(value):
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def check_output(path: str | os.PathLike, *, variance: bool = False, png: str | os.PathLike | None = None) -> None:
    """Fail early (before a render) for an output that :func:`write_render` could not write."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in (*LINEAR_FORMATS, ".png"):
        raise ImageError(f"{p}: unsupported output format {ext or '(none)'}; use .exr, .hdr, .pfm or .png")
    if variance and ext != ".exr":
        raise ImageError(f"{p}: a variance channel needs an .exr output")
    if png is not None and Path(png).suffix.lower() != ".png":
        raise ImageError(f"{png}: the preview must be a .png file")
    for target in (p, Path(png) if png is not None else None):
        if target is not None and target.exists() and target.is_dir():
            raise ImageError(f"{target}: is a directory")


def write_render(
    path: str | os.PathLike,
    result,
    *,
    variance: bool = False,
    exposure: float = 0.0,
    png: str | os.PathLike | None = None,
    sidecar: bool = True,
    extra: dict | None = None,
) -> list[Path]:
    """Write ``result`` (a :class:`~lightprobe.integrators.wavefront.RenderResult`) to ``path``.

    ``.exr``/``.hdr``/``.pfm`` are linear (``variance=True`` adds the variance of the mean as channels
    ``variance.R/G/B`` to an EXR); ``.png`` is tone mapped with ``exposure`` stops.  ``png`` writes an extra
    tone-mapped preview.  Returns the files written.
    """
    check_output(path, variance=variance, png=png)
    p = Path(path)
    ext = p.suffix.lower()
    written = []
    image = np.nan_to_num(result.image, nan=0.0, posinf=0.0, neginf=0.0)
    if ext in LINEAR_FORMATS:
        if variance:
            if ext != ".exr":
                raise ImageError(f"{p}: a variance channel needs an .exr output")
            data = np.concatenate([image, result.variance], axis=2)
            written.append(write_image(p, data, channel_names=VARIANCE_CHANNELS))
        else:
            written.append(write_image(p, image))
    elif ext == ".png":
        written.append(write_png(p, image, exposure=exposure))
    else:
        raise ImageError(f"{p}: unsupported output format {ext or '(none)'}; use .exr, .hdr, .pfm or .png")
    if png is not None:
        written.append(write_png(png, image, exposure=exposure))
    if sidecar:
        meta = {
            "lightprobe": __version__,
            "output": str(p),
            "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
            **result.stats,
            **(extra or {}),
        }
        side = p.with_name(p.name + ".json")
        side.write_text(json.dumps(_json_safe(meta), indent=2) + "\n")
        written.append(side)
    return written
