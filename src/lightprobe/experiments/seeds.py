"""The seeds' comparisons on rendered images, each cell a :func:`~lightprobe.experiments.compare.compare` report.

``krivanek-mis``
    Krivanek's exercise: a Phong sphere (rho_d = 0, rho_s = 1, so the exponent alone sets the lobe) alone in
    the map (no ground, whose diffuse shading would dominate the error), for each map and exponent; BRDF
    sampling, environment sampling and MIS (balance and power) at equal samples.  The seed's claim: BRDF
    sampling wins for sharp lobes, environment sampling for broad ones under spiky maps, and MIS is never far
    from the better of the two (its robustness).
``pbrt-envmap-vs-cosine``
    pbrt's InfiniteAreaLightIS chapter: a diffuse scene under a spiky map and under a soft one, cosine-weighted
    hemisphere sampling against the environment's importance sampling at equal samples; the variance reduction
    factor is MSE(cosine) / MSE(env).

Without ``../shared/data`` the maps are procedural: a sky with a 2-degree sun (spiky) and the same sky without it
(soft).  Every cell writes an HTML report; ``index.html`` links them under a table of all rows.
"""

from __future__ import annotations

import functools
import html
import json
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

from ..analysis.report import write_report
from ..bsdfs import Lambert, Phong
from ..emitters.envmap import EnvironmentMap
from ..emitters.procedural import sky_with_sun
from ..errors import LightprobeError, LightprobeWarning
from ..geometry.camera import Camera
from ..geometry.shapes import Rectangle, Sphere
from ..integrators.wavefront import RenderSettings, render
from ..scene import Scene
from .compare import compare

__all__ = ["Row", "environment", "krivanek_mis", "pbrt_envmap_vs_cosine"]


@dataclass(frozen=True)
class Row:
    experiment: str
    map: str
    material: str
    strategy: str
    spp: float
    seconds: float
    mse: float
    relmse: float
    efficiency: float
    report: str


@functools.lru_cache(maxsize=2)  # one map serves every cell of a row (and stays loaded in a Dask worker)
def environment(name: str) -> EnvironmentMap:
    """A named real map (``lightprobe.data.NAMED_ENVMAPS``), a file, or the procedural ``sky-sun`` / ``sky``."""
    if name == "sky-sun":
        return EnvironmentMap.from_array(sky_with_sun(width=256, height=128, sun_diameter_deg=2.0), source=name)
    if name == "sky":
        return EnvironmentMap.from_array(sky_with_sun(width=256, height=128, sun_radiance=(0.0, 0.0, 0.0)), source=name)
    from ..data import NAMED_ENVMAPS, named_envmap_path

    path = named_envmap_path(name) if name in NAMED_ENVMAPS else Path(name)
    if not Path(path).exists():
        raise LightprobeError(f"map {name!r} not found (../shared/data absent?); use sky-sun or sky")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LightprobeWarning)  # lossy-EXR ringing clamped: irrelevant here
        return EnvironmentMap.load(path)


def _sphere_scene(env: EnvironmentMap, bsdf, width: int, *, ground: bool) -> Scene:
    """The material on a sphere that fills most of the frame, optionally on a grey diffuse ground (which casts
    nothing on the sphere's lit side and shows the map's shadows)."""
    height = max(1, width * 3 // 4)
    scene = Scene(Camera([0, 0.9, 3.6], [0, 0.75, 0], fov=40, resolution=(width, height)), env, name="seed sphere")
    if ground:
        scene.add(Rectangle([-2.5, 0, 2.5], [5, 0, 0], [0, 0, -5]), Lambert(0.5), name="ground")
    scene.add(Sphere([0, 0.75, 0], 0.75), bsdf, name="sphere")
    return scene


def _material(spec: tuple[str, float]):
    kind, value = spec
    return Phong(0.0, 1.0, value) if kind == "phong" else Lambert(value)


def _cell(
    experiment: str,
    map_name: str,
    material: tuple[str, float],
    strategies: list[str],
    *,
    spp: int,
    reference_spp: int,
    seed: int,
    width: int,
    out: Path,
) -> list[Row]:
    """One (map, material) cell: its scene, reference, comparison and report.  Self-contained (it builds its own
    scene), so that it can run as a Dask task."""
    scene = _sphere_scene(environment(map_name), _material(material), width, ground=material[0] == "lambert")
    label = f"{material[0]} {'n=' if material[0] == 'phong' else ''}{material[1]:g}"
    ref = render(scene, RenderSettings(spp=reference_spp, seed=seed + 1_000_003))
    runs = compare(scene, strategies, ref.image, ref.variance, base=RenderSettings(seed=seed), spp=spp)
    name = f"{map_name}-{label}".replace("/", "_").replace(" ", "_")
    report = out / f"{name}.html"
    write_report(
        report,
        title=f"{experiment}: {map_name}, {label}, {spp} spp each",
        runs=runs,
        reference=ref.image,
        command=f"lightprobe experiment {experiment} (cell {map_name}, {label})",
        settings={"spp": spp, "reference_spp": reference_spp, "seed": seed, "resolution": scene.camera.resolution},
        notes=f"Reference: MIS, {reference_spp} spp.",
    )
    return [
        Row(
            experiment,
            map_name,
            label,
            r.label,
            r.spp,
            r.seconds,
            r.metrics["mse"],
            r.metrics["relmse"],
            r.metrics["efficiency"],
            report.name,
        )
        for r in runs
    ]


def _run_cells(cells: list[dict], dask: str | None, workers: int, progress: Callable[[str], None] | None):
    """Every cell here, in order, or as tasks on Dask distributed (``"local"``: a LocalCluster of ``workers``
    processes with one thread each; else a scheduler address whose workers share this file system)."""
    if dask is None:
        rows: list[Row] = []
        for cell in cells:
            if progress is not None:
                progress(f"{cell['experiment']}: {cell['map_name']}, {cell['material'][0]} {cell['material'][1]:g}")
            rows += _cell(**cell)
        return rows
    from ..analysis.distributed import dask_client

    if progress is not None:
        progress(f"{len(cells)} cells as Dask tasks on {dask if dask != 'local' else f'{workers} local workers'}")
    with dask_client(None if dask == "local" else dask, workers) as client:
        parts = client.gather([client.submit(_cell, **cell, pure=False) for cell in cells])
    return [row for part in parts for row in part]  # in cell order, whatever finished first


def _index(out: Path, title: str, rows: list[Row], summary: str) -> Path:
    lines = [
        "<!doctype html>",
        f'<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>',
        "<style>body{font:14px system-ui,sans-serif;margin:24px}td,th{border:1px solid #ccc;padding:3px 8px}"
        "table{border-collapse:collapse}</style></head><body>",
        f"<h1>{html.escape(title)}</h1><p>{html.escape(summary)}</p><table><tr><th>map</th><th>material</th>"
        "<th>strategy</th><th>spp</th><th>seconds</th><th>MSE</th><th>relMSE</th><th>efficiency</th></tr>",
    ]
    for r in rows:
        lines.append(
            f"<tr><td>{html.escape(r.map)}</td><td>{html.escape(r.material)}</td><td>"
            f'<a href="{html.escape(r.report)}">{html.escape(r.strategy)}</a></td><td>{r.spp:g}</td>'
            f"<td>{r.seconds:.3f}</td><td>{r.mse:.3g}</td><td>{r.relmse:.3g}</td><td>{r.efficiency:.3g}</td></tr>"
        )
    lines.append("</table></body></html>")
    path = out / "index.html"
    path.write_text("\n".join(lines), encoding="utf-8")
    (out / "rows.json").write_text("\n".join(json.dumps(asdict(r)) for r in rows) + "\n")
    return path


def _experiment(
    name: str,
    maps: list[str],
    materials: list[tuple[str, float]],
    strategies: list[str],
    out: Path,
    summary: str,
    options: dict,
    dask: str | None,
    workers: int,
    progress: Callable[[str], None] | None,
) -> list[Row]:
    out.mkdir(parents=True, exist_ok=True)
    for map_name in maps:
        environment(map_name)  # a missing map fails here, before any work
    cells = [
        {"experiment": name, "map_name": m, "material": material, "strategies": strategies, "out": out, **options}
        for m in maps
        for material in materials
    ]
    rows = _run_cells(cells, dask, workers, progress)
    _index(out, name, rows, summary)
    return rows


def krivanek_mis(
    maps: list[str],
    exponents: list[float],
    out: Path,
    *,
    spp: int = 64,
    reference_spp: int = 1024,
    width: int = 96,
    seed: int = 1,
    progress: Callable[[str], None] | None = None,
    dask: str | None = None,
    workers: int = 2,
) -> list[Row]:
    """Rows for every (map, Phong exponent, strategy); reports in ``out``; cells on Dask with ``dask``."""
    return _experiment(
        "krivanek-mis",
        maps,
        [("phong", float(n)) for n in exponents],
        ["brdf", "env", "mis-balance", "mis-power"],
        out,
        "Phong sphere (rho_d 0, rho_s 1) per map and exponent; equal samples.",
        {"spp": spp, "reference_spp": reference_spp, "seed": seed, "width": width},
        dask,
        workers,
        progress,
    )


def pbrt_envmap_vs_cosine(
    maps: list[str],
    out: Path,
    *,
    spp: int = 64,
    reference_spp: int = 1024,
    width: int = 96,
    seed: int = 1,
    progress: Callable[[str], None] | None = None,
    dask: str | None = None,
    workers: int = 2,
) -> list[Row]:
    """Rows for cosine and environment sampling of a diffuse scene under each map; reports in ``out``."""
    return _experiment(
        "pbrt-envmap-vs-cosine",
        maps,
        [("lambert", 0.7)],
        ["cosine", "env"],
        out,
        "Diffuse scene; variance reduction = MSE(cosine) / MSE(env).",
        {"spp": spp, "reference_spp": reference_spp, "seed": seed, "width": width},
        dask,
        workers,
        progress,
    )


def reduction_factors(rows: list[Row]) -> dict[str, float]:
    """MSE(cosine) / MSE(env) per map, from pbrt-envmap-vs-cosine rows."""
    by = {(r.map, r.strategy): r.mse for r in rows}
    maps = sorted({r.map for r in rows})
    return {m: by[(m, "cosine")] / by[(m, "env")] for m in maps if by.get((m, "env"), 0) > 0}
