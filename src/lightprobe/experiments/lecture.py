"""The lecture's two claims about area and many lights, measured on rendered images.

``lecture-area-sampling``
    A 1 x 1 rectangular light over a grey ground with a sphere and a box-like blob casting soft shadows (the
    lecture's "direct lighting: area sampling" picture): the light sampled by uniform hemisphere directions,
    uniform points on its area, and uniform directions in its solid angle (Urena et al. 2013), with 1 and 16
    shadow rays per camera sample.  Light sampling only, no MIS, as in the lecture.
``lecture-many-lights``
    The built-in many-light scene (4,000 emissive triangles, in quads and singly, over four decades of power):
    K = 16 lights picked per camera sample, N = 1 sample each, by uniform, power-proportional and light-BVH
    selection.  The lecture reports 12.4x lower MSE for power over uniform on its scene.

Each row is measured against a reference rendered with MIS (power heuristic, BVH selection, solid-angle light
sampling) at many samples; MSE and relMSE (the peer kit's (x - ref)^2 / (ref^2 + 0.01)) are means over pixels and
channels.  Every image is written as a PNG beside a JSON file of the rows.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..bsdfs import Lambert, RoughPlastic
from ..geometry.camera import Camera
from ..geometry.shapes import Rectangle, Sphere
from ..integrators.wavefront import RenderSettings, render
from ..scene import Scene

__all__ = ["Row", "area_sampling", "area_sampling_scene", "many_lights", "to_json_lines", "to_markdown"]


@dataclass(frozen=True)
class Row:
    """One measured configuration."""

    experiment: str
    strategy: str
    shadow_rays_per_sample: int
    spp: int
    seconds: float
    rays: int
    mse: float
    relmse: float
    mse_ratio_to_best: float = 1.0
    efficiency: float = 0.0  # 1 / (MSE x seconds)


def _errors(image: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    diff = image.astype(np.float64) - reference
    return float(np.mean(diff**2)), float(np.mean(diff**2 / (reference.astype(np.float64) ** 2 + 0.01)))


def area_sampling_scene(resolution=(320, 240)) -> Scene:
    from ..demo import blob_mesh

    scene = Scene(Camera([0.0, 2.2, 4.2], [0.0, 0.4, 0.0], fov=40.0, resolution=resolution), name="area light")
    scene.add(Rectangle.ground(size=30.0), Lambert(0.6), name="ground")
    scene.add(Sphere([-0.7, 0.45, 0.2], 0.45), Lambert([0.7, 0.3, 0.2]), name="sphere")
    scene.add(blob_mesh(3), RoughPlastic([0.2, 0.4, 0.7], 0.3), transform={"scale": 0.45, "translate": [0.8, 0.5, 0]})
    # a 1 x 1 light 1.8 above the ground, facing down: (+X) x (+Z) = -Y
    scene.add(Rectangle([-0.5, 1.8, -0.6], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]), emission=12.0, name="light")
    return scene


def _measure(experiment, scene, settings, label, reference, out_dir: Path | None) -> Row:
    result = render(scene, settings)
    mse, rel = _errors(result.image, reference)
    rays = int(result.stats["rays"])
    if out_dir is not None:
        from ..images import write_png

        write_png(out_dir / f"{experiment}-{label}.png", result.image)
    return Row(experiment, label, settings.light_samples, settings.spp, result.stats["seconds"], rays, mse, rel)


def _reference(scene, spp: int, seed: int, out_dir: Path | None, name: str, **options) -> np.ndarray:
    settings = RenderSettings(spp=spp, strategy="mis", light_sampler="bvh", seed=seed, **options)
    image = render(scene, settings).image.astype(np.float64)
    if out_dir is not None:
        from ..images import write_image, write_png

        write_png(out_dir / f"{name}-reference.png", image)
        write_image(out_dir / f"{name}-reference.exr", image)
    return image


def _ratios(rows: list[Row]) -> list[Row]:
    best = min(r.mse for r in rows)
    return [
        Row(
            **{
                **asdict(r),
                "mse_ratio_to_best": r.mse / best if best > 0 else float("inf"),
                "efficiency": 1.0 / (r.mse * r.seconds) if r.mse > 0 and r.seconds > 0 else float("inf"),
            }
        )
        for r in rows
    ]


def area_sampling(
    *, spp: int = 4, reference_spp: int = 1024, seed: int = 1, resolution=(320, 240), out_dir=None
) -> list[Row]:
    """Hemisphere vs area vs solid-angle sampling of a rectangular light, 1 and 16 shadow rays per camera sample."""
    out = _out(out_dir)
    scene = area_sampling_scene(resolution)
    reference = _reference(scene, reference_spp, seed + 1000, out, "lecture-area-sampling", n_env=4)
    rows = []
    for rays in (1, 16):
        for light_strategy in ("hemisphere", "area", "solid-angle"):
            settings = RenderSettings(
                spp=spp, strategy="env", light_strategy=light_strategy, n_bsdf=0, n_env=rays, seed=seed
            )
            row = _measure("lecture-area-sampling", scene, settings, f"{light_strategy}-{rays}", reference, out)
            rows.append(row)
    return _ratios(rows)


def many_lights(
    *,
    n_lights: int = 4000,
    spp: int = 1,
    k: int = 16,
    reference_spp: int = 256,
    seed: int = 1,
    resolution=(320, 212),
    out_dir=None,
) -> list[Row]:
    """Uniform vs power vs BVH light selection on the many-light demo, K lights per camera sample, N = 1."""
    from ..demo import many_lights_scene

    out = _out(out_dir)
    scene = many_lights_scene(n_lights, resolution=resolution, view="lit")
    reference = _reference(scene, reference_spp, seed + 1000, out, "lecture-many-lights", lights_per_sample=4)
    rows = []
    for selector in ("uniform", "power", "bvh"):
        settings = RenderSettings(
            spp=spp, strategy="env", light_sampler=selector, lights_per_sample=k, n_bsdf=0, n_env=1, seed=seed
        )
        row = _measure("lecture-many-lights", scene, settings, selector, reference, out)
        rows.append(row)
    return _ratios(rows)


def _out(out_dir) -> Path | None:
    if out_dir is None:
        return None
    p = Path(out_dir)
    p.mkdir(parents=True, exist_ok=True)
    return p


def to_markdown(rows: list[Row]) -> str:
    lines = [
        "| strategy | shadow rays / sample | spp | seconds | rays | MSE | relMSE | MSE / best |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.strategy} | {r.shadow_rays_per_sample} | {r.spp} | {r.seconds:.2f} | {r.rays} | {r.mse:.4g} | "
            f"{r.relmse:.4g} | {r.mse_ratio_to_best:.3g} |"
        )
    return "\n".join(lines)


def to_json_lines(rows: list[Row]) -> str:
    return "\n".join(json.dumps(asdict(r)) for r in rows)
