"""Writing renders: linear EXR/HDR/PFM (optionally with per-pixel variance), tone-mapped PNG, JSON sidecar.

Writing is safe: every file is checked before the render (:func:`check_output`), written under a temporary
name and renamed into place (a failed write never leaves a truncated file or clobbers an older one), and a render
whose output cannot be written after all is rescued to another folder rather than lost.

The sidecar (``<output>.json``) records the settings, timings and throughput (seconds, samples/s, rays/s), the
samples actually taken per pixel, and whether the render was interrupted or stopped by its time limit.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import ImageError
from ..images import LINEAR_FORMATS, write_image, write_png

__all__ = ["check_output", "write_render"]

VARIANCE = ("R", "G", "B", "variance.R", "variance.G", "variance.B")


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


def check_output(
    path: str | os.PathLike,
    *,
    variance: bool = False,
    png: str | os.PathLike | None = None,
    resolution: tuple[int, int] | None = None,
) -> None:
    """Fail early, before a render, for an output that :func:`write_render` could not write.

    Checks the extension, that each file (the image, the PNG preview, the JSON sidecar) is not a folder, that its
    folder exists or can be made and accepts a new file (a real probe file, so read-only folders, read-only file
    systems and missing permissions are all caught), and, when ``resolution`` is given, that the disk has room
    for the image.  Raises :class:`~lightprobe.errors.ImageError` naming the path.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in (*LINEAR_FORMATS, ".png"):
        raise ImageError(f"{p}: unsupported output format {ext or '(none)'}; use .exr, .hdr, .pfm or .png")
    if variance and ext != ".exr":
        raise ImageError(f"{p}: a variance channel needs an .exr output")
    if png is not None and Path(png).suffix.lower() != ".png":
        raise ImageError(f"{png}: the preview must be a .png file")
    targets = [p, _sidecar(p)] + ([Path(png)] if png is not None else [])
    for target in targets:
        _check_writable(target)
    if resolution is not None:
        width, height = resolution
        channels = 6 if variance else 3
        needed = width * height * channels * 4 + width * height * 3 * (png is not None) + 65536
        for folder in {t.parent for t in targets}:
            free = shutil.disk_usage(folder).free
            if free < needed:
                raise ImageError(
                    f"{p}: not enough free space in {folder} ({free / 1e6:.1f} MB free, the output needs up to "
                    f"{needed / 1e6:.1f} MB)"
                )


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".json")


def _check_writable(target: Path) -> None:
    if target.is_dir():
        raise ImageError(f"{target}: is a folder")
    folder = target.parent
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ImageError(f"{target}: cannot write: {existing} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".lightprobe-probe-"):
            pass
        if target.exists():
            with open(target, "r+b"):  # an existing read-only file
                pass
    except OSError as exc:
        raise ImageError(f"{target}: cannot write ({exc.strerror or exc})") from None


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

    A finished render is never lost: if the image cannot be written (the disk filled up during the render), the
    render goes to a rescue EXR (with its variance) in the current folder, or the temporary folder if that fails
    too, and the :class:`~lightprobe.errors.ImageError` raised says where it is.
    """
    check_output(path, variance=variance, png=png)
    p = Path(path)
    ext = p.suffix.lower()
    written = []
    image = np.nan_to_num(result.image, nan=0.0, posinf=0.0, neginf=0.0)
    meta = {
        "lightprobe": __version__,
        "output": str(p),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        **result.stats,
        **(extra or {}),
    }
    try:
        if ext == ".png":
            written.append(write_png(p, image, exposure=exposure))
        elif variance:
            written.append(write_image(p, np.concatenate([image, result.variance], axis=2), channel_names=VARIANCE))
        else:
            written.append(write_image(p, image))
    except (ImageError, OSError) as exc:
        reason = str(exc).removeprefix(f"{p}: ")
        rescue = _rescue(p, image, result.variance, meta)
        raise ImageError(f"{p}: cannot write ({reason}); the render was saved to {rescue} instead") from None
    if png is not None:
        written.append(write_png(png, image, exposure=exposure))
    if sidecar:
        written.append(_write_json(_sidecar(p), meta))
    return written


def _write_json(path: Path, meta: dict) -> Path:
    try:
        path.write_text(json.dumps(_json_safe(meta), indent=2) + "\n")
    except OSError as exc:
        raise ImageError(f"{path}: cannot write ({exc.strerror or exc})") from None
    return path


def _rescue(path: Path, image: np.ndarray, variance: np.ndarray, meta: dict) -> Path:
    """Write the render (mean and variance, linear EXR) and its sidecar where it can go: the current folder,
    else the temporary folder.  Returns the image's path; raises if neither folder takes it."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    name = f"lightprobe-rescued-{path.stem}-{stamp}-{os.getpid()}.exr"
    failures = []
    for folder in (Path.cwd(), Path(tempfile.gettempdir())):
        target = folder / name
        try:
            write_image(target, np.concatenate([image, variance], axis=2), channel_names=VARIANCE)
            _write_json(_sidecar(target), {**meta, "output": str(target), "intended_output": str(path)})
            return target
        except (ImageError, OSError) as exc:
            failures.append(str(exc))
    raise ImageError(f"{path}: cannot write, and no rescue copy could be written either ({'; '.join(failures)})")
