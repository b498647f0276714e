"""Sample ranges of a render as tasks on Dask distributed: references beyond one process, or one machine.

A render of samples 0 ... spp - 1 splits into ranges [a, b); each range is one task that renders it from scratch
(every random number is a pure function of its seed, pixel, sample index and dimension, so a range rendered on any
worker gives the same numbers) and returns its per-pixel statistics.  The ranges are merged in range order with
Chan, Golub and LeVeque's pairwise update, so the result does not depend on which worker finished first, and equals
a single-process render up to float64 rounding.  A render that learns its light selection learns it from its first
samples (integrators/light_learning.py): the range that holds them is rendered first, and the other ranges pick
with what it learned, as the single process does after its pilot.  Dask's scheduler re-runs the task of a worker
that is lost; the other ranges are kept.  No job queue of our own: a ``LocalCluster`` by default, or any scheduler
address.
"""

from __future__ import annotations

import contextlib
import dataclasses

from ..errors import LightprobeError
from ..integrators.light_learning import first_range
from ..integrators.wavefront import (
    Accumulator,
    RenderResult,
    RenderSettings,
    learns_light_selection,
    render,
    result_from,
    settings_for,
)
from ..scene import Scene

__all__ = ["dask_client", "render_on_dask", "sample_ranges"]


def sample_ranges(spp: int, chunk: int, first: int = 0) -> list[tuple[int, int]]:
    """[(first sample, count), ...] covering first ... first + spp - 1 in chunks of at most ``chunk``."""
    if spp < 1 or chunk < 1:
        raise LightprobeError(f"spp and chunk must be >= 1, got {spp} and {chunk}")
    return [(a, min(chunk, first + spp - a)) for a in range(first, first + spp, chunk)]


def _render_range(
    scene: Scene, settings: RenderSettings, first: int, count: int, learned: dict | None = None
) -> tuple[dict, float]:
    part = dataclasses.replace(settings.uniform_unless_adaptive(), spp=count, first_sample=first, time_limit=None)
    result = render(scene, part, learned=learned)
    return result.accumulator.to_arrays(), result.stats["seconds"]


def _pilot_range(ranges: list[tuple[int, int]], spp: int) -> list[tuple[int, int]]:
    """``ranges`` with the first one long enough to learn the light selection as a single render of ``spp`` samples
    does (``light_learning.first_range``)."""
    first, count = ranges[0]
    wanted = first_range(count, spp)
    if count >= wanted:
        return ranges
    return [(first, wanted), *(sample_ranges(spp - wanted, count, first + wanted) if spp > wanted else [])]


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int = 2, threads_per_worker: int = 1, connect_timeout: float = 20.0):
    """A Dask client: of the scheduler at ``scheduler``, or of a ``LocalCluster`` of ``workers`` processes (closed
    on exit).  One :class:`LightprobeError` line when Dask is missing or the scheduler cannot be reached."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise LightprobeError("Dask distributed is not installed: pip install 'dask[distributed]'") from None
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=threads_per_worker, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout=f"{connect_timeout}s")
        except OSError as exc:
            raise LightprobeError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def render_on_dask(
    scene: Scene,
    settings: RenderSettings,
    *,
    chunk: int = 16,
    scheduler: str | None = None,
    workers: int = 2,
    threads_per_worker: int = 1,
    resume: Accumulator | None = None,
    connect_timeout: float = 20.0,
) -> RenderResult:
    """Render ``settings.spp`` samples per pixel (from ``settings.first_sample``) as ranges of ``chunk`` on Dask:
    the scheduler at ``scheduler`` (e.g. ``tcp://10.0.0.5:8786``), or a ``LocalCluster`` of ``workers`` processes
    with ``threads_per_worker`` threads each.  ``resume`` is merged in front (its samples must come before).
    ``connect_timeout``: seconds to wait for a remote scheduler.  The ranges are uniform (spp samples in every
    pixel): adaptive counts need the whole pilot first, so they are refused."""
    settings = settings.uniform_unless_adaptive()
    if settings.adaptive:
        raise LightprobeError("a render split into sample ranges cannot take adaptive counts: leave adaptive off")
    settings.validate()
    if settings.lights_per_sample is None:
        # every range picks as many lights as the whole render (a probe may choose K: integrators/picks.py, whose
        # rule sees a range's own samples)
        settings = dataclasses.replace(settings, lights_per_sample=settings_for(scene, settings).lights_per_sample)
    ranges = sample_ranges(settings.spp, chunk, settings.first_sample)
    learned = resume.learned if resume is not None else None
    # a range from sample 0 of a render that learns: rendered first, and what it learned goes to the other ranges
    learns_first = learned is None and settings.first_sample == 0 and learns_light_selection(scene, settings)
    if learns_first:
        ranges = _pilot_range(ranges, settings.spp)
    with dask_client(scheduler, workers, threads_per_worker, connect_timeout) as client:
        per_task = dataclasses.replace(settings, threads=settings.threads or threads_per_worker)
        scene_on_workers = client.scatter(scene, broadcast=True)
        parts = []
        if learns_first:
            (a, n), ranges = ranges[0], ranges[1:]
            parts.append(client.submit(_render_range, scene_on_workers, per_task, a, n, pure=False).result())
            learned = Accumulator.from_arrays(parts[0][0]).learned
        # pure=False: every call gets fresh task keys, never another render's cached result
        futures = [
            client.submit(_render_range, scene_on_workers, per_task, a, n, learned, pure=False) for a, n in ranges
        ]
        parts += client.gather(futures)
    acc = resume
    for arrays, _ in parts:  # in range order: the merge does not depend on which task finished first
        part = Accumulator.from_arrays(arrays)
        acc = part if acc is None else acc.merged(part)
    width, height = scene.camera.resolution
    stats = {
        "ranges": len(parts),
        "chunk": chunk,
        "task_seconds": sum(seconds for _, seconds in parts),
        "scheduler": scheduler or f"LocalCluster({workers} x {threads_per_worker})",
        "spp_done": int(acc.count.min()),
    }
    return result_from(acc, width, height, stats)
