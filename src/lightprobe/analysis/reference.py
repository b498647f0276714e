"""References that survive interruption: a render accumulated in sample ranges, checkpointed to disk, resumable.

``render_reference(scene, settings, out)`` renders samples ``0 ... spp - 1`` in chunks of ``chunk`` samples per
pixel.  After each chunk the running statistics (per-pixel float64 mean, M2, sample and non-finite counts) go to
``<out>.checkpoint.npz`` beside the image, written to a temporary file and renamed into place, so a crash or a
kill leaves either the old checkpoint or the new one.  Run again with the same settings and it resumes from the
checkpoint's sample count; since every random number is a pure function of (seed, pixel, sample index,
dimension) and the statistics continue in sample order, the result is bit for bit that of an uninterrupted run.
A larger ``spp`` extends a finished reference the same way.  A checkpoint made with other settings (seed,
sampler, strategy, scene, resolution; the settings compared with their automatic choices made for the scene) is an
error naming the file and the difference, never silently mixed in.
A chunk in flight when Ctrl-C or the time limit stops the render is not checkpointed (its pixels have uneven
sample counts); at most one chunk of work is redone on resume.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import LightprobeError
from ..integrators.light_learning import first_range
from ..integrators.settings import DIFFUSE, RESOLVED_PER_SCENE
from ..integrators.wavefront import (
    Accumulator,
    RenderResult,
    RenderSettings,
    compensation_for,
    learns_light_selection,
    lit_by_the_map_alone,
    render,
    result_from,
    settings_for,
)
from ..scene import Scene

__all__ = ["checkpoint_path", "render_reference"]

# settings that may change between runs of one reference without changing its samples
_FREE = {"spp", "first_sample", "time_limit", "threads", "pass_samples"}


def checkpoint_path(out: str | os.PathLike) -> Path:
    p = Path(out)
    return p.with_name(p.name + ".checkpoint.npz")


def _identity(scene: Scene, settings: RenderSettings, scene_id: str) -> dict:
    """What a checkpoint's samples depend on: the settings with the automatic choices made for this scene (an
    automatic count whose rule changed between versions, as decision 97's K and BSDF samples did, is a different
    render, not the same None), the resolution and the scene."""
    resolved = settings_for(scene, settings)
    fixed = {k: v for k, v in dataclasses.asdict(resolved).items() if k not in _FREE}
    width, height = scene.camera.resolution
    return {
        "settings": fixed,
        "resolution": [width, height],
        "scene": scene_id,
        "counts": "resolved",
        "compensation": compensation_for(scene, resolved),
    }


def _older_compensation(meta: dict, scene: Scene) -> bool | str:
    """The MIS compensation a checkpoint written before checkpoints recorded it rendered with: the automatic choice
    was the Lambertian materials under MIS with an environment map as the only light, and none otherwise (a map
    beside other lights has been compensated since decisions.md 98)."""
    settings = meta.get("settings", {})
    if settings.get("mis_compensation") is not None:
        return settings["mis_compensation"]
    one_pick = settings.get("lights_per_sample") in (None, 1)
    return DIFFUSE if settings.get("strategy") == "mis" and lit_by_the_map_alone(scene) and one_pick else False


def _damaged(path: Path, why: str) -> LightprobeError:
    """The error for a checkpoint that cannot be used as it is; the file is left alone (it may hold hours of
    samples that another tool can still rescue)."""
    why = " ".join(why.split())  # one line, whatever the library's message held
    return LightprobeError(
        f"{path}: damaged checkpoint ({why}); remove it to start over, or choose another -o to keep it"
    )


#: what reading a damaged .npz can raise: numpy's parsers (ValueError, EOFError), zipfile's checks (a bad CRC, a
#: cut-short member), a compression method or a member name it does not know, the disk itself
_DAMAGE = (OSError, EOFError, ValueError, KeyError, NotImplementedError, zipfile.BadZipFile, zlib.error)


def _read_checkpoint(path: Path) -> tuple[dict, Accumulator]:
    """A checkpoint's identity and accumulator, or a :func:`_damaged` error naming what is wrong with the file: cut
    short, overwritten, empty, not an .npz archive, or arrays of the wrong shapes."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
        if not head:
            raise _damaged(path, "the file is empty")
        # numpy takes a file that does not start as a zip archive for a pickle and says so, which misleads
        if head != b"PK\x03\x04" or not zipfile.is_zipfile(path):
            size = path.stat().st_size
            raise _damaged(path, f"{size} bytes that are not an .npz archive: cut short or overwritten")
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["identity"]))
            acc = Accumulator.from_arrays(data)
    except _DAMAGE as exc:
        why = f"no {exc.args[0]!r} array" if isinstance(exc, KeyError) else str(exc) or type(exc).__name__
        raise _damaged(path, why) from None
    if not isinstance(meta, dict) or not isinstance(meta.get("settings", {}), dict):
        raise _damaged(path, "its identity is not a table of settings")
    n = acc.count.shape[0] if acc.count.ndim == 1 else -1
    if n < 0 or acc.mean.shape != (n, 3) or acc.m2.shape != (n, 3) or acc.nonfinite.shape != (n,):
        shapes = ", ".join(f"{k} {v.shape}" for k, v in acc.to_arrays().items() if k != "adaptive")
        raise _damaged(path, f"arrays of mismatched shapes: {shapes}")
    return meta, acc


def _load(path: Path, identity: dict, n_pixels: int, scene: Scene) -> Accumulator | None:
    if not path.exists():
        return None
    meta, acc = _read_checkpoint(path)
    if "counts" not in meta:  # written before checkpoints recorded their settings as resolved
        left = sorted(k for k in RESOLVED_PER_SCENE if meta.get("settings", {}).get(k, 0) is None)
        if left:
            raise LightprobeError(
                f"{path}: checkpoint of an older lightprobe that left {', '.join(left)} automatic, which this version "
                "may choose differently; finish it with that version, or move it away to start afresh"
            )
        meta = {**meta, "counts": "resolved"}  # every count was given: what it recorded is what it rendered
    if "compensation" not in meta:  # written before checkpoints recorded the compensation
        meta = {**meta, "compensation": _older_compensation(meta, scene)}
    if meta != identity:
        diff = sorted(
            k
            for k in set(meta.get("settings", {})) | set(identity["settings"])
            if meta.get("settings", {}).get(k) != identity["settings"].get(k)
        )
        if meta.get("resolution") != identity["resolution"]:
            diff.append("resolution")
        if meta.get("scene") != identity["scene"]:
            diff.append("scene")
        if meta.get("compensation") != identity["compensation"]:  # automatic, its rule changed (decisions.md 98)
            diff.append("mis_compensation")
        given = meta.get("settings", {})
        values = "".join(  # what each setting was and is: e.g. a default that changed since (decisions.md 117)
            f"{k} {given.get(k)!r} in the checkpoint, {identity['settings'].get(k)!r} now; "
            for k in diff
            if k in given or k in identity["settings"]
        )
        raise LightprobeError(
            f"{path}: checkpoint of a different render ({', '.join(diff) or 'settings'} differ): {values}"
            "use the same settings, or move it away to start afresh"
        )
    if acc.count.size != n_pixels or acc.count.min() != acc.count.max():
        raise _damaged(path, f"{acc.count.size} pixels' counts, {n_pixels} pixels of even counts expected")
    return acc


def _save(path: Path, acc: Accumulator, identity: dict) -> None:
    tmp = path.with_name(f".{path.name}.partial-{os.getpid()}.npz")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, identity=np.array(json.dumps(identity)), **acc.to_arrays())
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        raise LightprobeError(f"{path}: cannot write the checkpoint ({exc.strerror or exc})") from None
    finally:
        tmp.unlink(missing_ok=True)


def render_reference(
    scene: Scene,
    settings: RenderSettings,
    out: str | os.PathLike,
    *,
    chunk: int = 16,
    scene_id: str = "",
    progress: Callable[[dict], None] | None = None,
    on_chunk: Callable[[int, int], None] | None = None,
    dask: str | None = None,
    workers: int = 2,
) -> RenderResult:
    """Render (or resume, or extend) ``settings.spp`` samples per pixel, checkpointing after every ``chunk``.

    ``scene_id`` names the scene in the checkpoint (e.g. a hash of the scene file), so that a checkpoint of
    another scene is refused.  ``settings.time_limit`` bounds this run; the result says how far it got
    (``stats['spp_done']``) and the checkpoint keeps it.  ``on_chunk(done, spp)`` is called after each checkpoint.

    ``dask``: render the missing chunks as tasks on Dask distributed instead (``"local"``: a LocalCluster of
    ``workers`` processes; else a scheduler address); they are merged in sample order onto the checkpoint, equal to
    the single-process result up to float64 rounding, and checkpointed once all have finished."""
    if chunk < 1:
        raise LightprobeError(f"chunk must be >= 1 sample per pixel, got {chunk}")
    settings = settings.uniform_unless_adaptive()  # checkpointed sample ranges: spp in every pixel
    if settings.adaptive:
        raise LightprobeError(
            "a reference is rendered in checkpointed sample ranges, which adaptive counts cannot be (they need the "
            "whole pilot first): leave adaptive off"
        )
    settings.validate()
    width, height = scene.camera.resolution
    identity = _identity(scene, settings, scene_id)
    if settings.lights_per_sample is None:
        # the chunks pick as many lights as the whole reference (a probe may choose K: integrators/picks.py, whose
        # rule sees a chunk's range, not the reference's)
        settings = dataclasses.replace(settings, lights_per_sample=identity["settings"]["lights_per_sample"])
    ckpt = checkpoint_path(out)
    acc = _load(ckpt, identity, width * height, scene)
    done = int(acc.count[0]) if acc is not None else 0
    resumed_from = done
    start = time.perf_counter()
    stats: dict = {}
    stopped = False
    if dask is not None and done < settings.spp:
        from .distributed import render_on_dask

        rest = dataclasses.replace(settings, spp=settings.spp - done, first_sample=done)
        merged = render_on_dask(
            scene, rest, chunk=chunk, scheduler=None if dask == "local" else dask, workers=workers, resume=acc
        )
        acc, stats, done = merged.accumulator, merged.stats, settings.spp
        _save(ckpt, acc, identity)
        if on_chunk is not None:
            on_chunk(done, settings.spp)
    # a render that learns its light selection learns it from its first samples where it has more: the first chunk
    # holds them and one more (light_learning.first_range), so that a reference in short chunks picks as one render
    first = first_range(chunk, settings.spp)
    if first <= chunk or done > 0 or not learns_light_selection(scene, settings):
        first = chunk
    while done < settings.spp:
        n = min(first if done == 0 else chunk, settings.spp - done)
        limit = None
        if settings.time_limit is not None:
            limit = settings.time_limit - (time.perf_counter() - start)
            if limit <= 0:
                stopped = True
                break
        part = dataclasses.replace(settings, spp=n, first_sample=done, time_limit=limit)
        result = render(scene, part, resume=acc, progress=progress)
        stats = result.stats
        if stats["interrupted"] or stats["stopped_by_time_limit"]:
            stopped = True  # the chunk in flight is not checkpointed (uneven counts): it is redone on resume
            break
        acc = result.accumulator
        done += n
        _save(ckpt, acc, identity)
        if on_chunk is not None:
            on_chunk(done, settings.spp)
    if acc is None:
        raise LightprobeError("stopped before the first chunk was finished; nothing to write")
    out_stats = {
        **{k: v for k, v in stats.items() if k not in ("spp_done", "spp_max")},
        "reference_spp": settings.spp,
        "resumed_from_spp": resumed_from,
        "stopped": stopped,
        "seconds_this_run": time.perf_counter() - start,
        "checkpoint": str(ckpt),
        "scene_id": scene_id,
        "chunk": chunk,
    }
    return result_from(acc, width, height, out_stats)


def file_id(path: str | os.PathLike) -> str:
    """A scene file's identity for checkpoints: the SHA-256 of its bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
