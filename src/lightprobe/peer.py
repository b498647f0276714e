"""The benchmark's peer scene (``../shared/peers/scene.json``), built from its renderer-independent description.

The assets (a 1024x512 sky with a 0.5-degree sun, a 98,000-triangle blob) come from the peer kit's own
deterministic generator, ``../shared/peers/mitsuba/scene_assets.py`` (NumPy only), so lightprobe and Mitsuba render
exactly the same data.  :func:`peer_scene` returns a :class:`~lightprobe.scene.Scene`.
"""

from __future__ import annotations

import importlib.util
import json
import os
from pathlib import Path

import numpy as np

from .bsdfs import GGXConductor, Lambert, RoughPlastic
from .emitters.envmap import EnvironmentMap
from .errors import SceneError
from .geometry.camera import Camera
from .geometry.mesh import TriangleMesh
from .geometry.shapes import Rectangle, Sphere
from .scene import Scene

__all__ = ["find_peers", "peer_assets", "peer_scene", "reference_floor", "variance_file"]


def find_peers() -> Path | None:
    """The peer kit folder (``LIGHTPROBE_PEERS``, ``../shared/peers`` from here or from the repository)."""
    candidates = []
    if os.environ.get("LIGHTPROBE_PEERS"):
        candidates.append(Path(os.environ["LIGHTPROBE_PEERS"]))
    candidates += [Path.cwd() / ".." / "shared" / "peers", Path(__file__).resolve().parents[3] / "shared" / "peers"]
    for c in candidates:
        if (c / "scene.json").is_file() and (c / "mitsuba" / "scene_assets.py").is_file():
            return c.resolve()
    return None


def _require_peers(peers: Path | None) -> Path:
    peers = peers or find_peers()
    if peers is None:
        raise SceneError("the peer kit (../shared/peers) was not found; set LIGHTPROBE_PEERS to its folder")
    return Path(peers)


def peer_assets(peers: Path | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(env image (512, 1024, 3) float32, blob vertices (V, 3), blob faces (F, 3)) from the kit's generator."""
    peers = _require_peers(peers)
    spec = importlib.util.spec_from_file_location("_peer_scene_assets", peers / "mitsuba" / "scene_assets.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    env, _ = module.make_envmap()
    vertices, faces = module.make_blob()
    return env, vertices, faces


def peer_scene(peers: Path | None = None, *, resolution: tuple[int, int] | None = None, **env_options) -> Scene:
    """The peer scene exactly as ``scene.json`` describes it (optionally at another resolution)."""
    peers = _require_peers(peers)
    desc = json.loads((peers / "scene.json").read_text())
    env_image, vertices, faces = peer_assets(peers)
    cam = desc["camera"]
    res = resolution or tuple(cam["resolution"])
    camera = Camera(
        cam["origin"], cam["target"], cam["up"], fov=cam["fov_deg"], fov_axis=cam["fov_axis"], resolution=res
    )
    environment = EnvironmentMap.from_array(env_image, source="peer env (scene_assets.make_envmap)", **env_options)
    scene = Scene(camera, environment, name="peer scene")
    mats = desc["materials"]
    scene.add_material("grey_diffuse", Lambert(mats["grey_diffuse"]["reflectance"]))
    scene.add_material("green_diffuse", Lambert(mats["green_diffuse"]["reflectance"]))
    plastic = mats["red_rough_plastic"]
    scene.add_material(
        "red_rough_plastic", RoughPlastic(plastic["diffuse_reflectance"], plastic["alpha"], eta=plastic["eta"])
    )
    for name in ("rough_aluminium", "rough_gold"):
        m = mats[name]
        scene.add_material(name, GGXConductor(m["alpha"], eta=m["eta"], k=m["k"]))
    for obj in desc["objects"]:
        if obj["shape"] == "rectangle":
            m = np.asarray(obj["to_world"], dtype=np.float64)
            # Mitsuba's rectangle is [-1, 1]^2 in z = 0 with normal +Z: corner (-1, -1), edges 2x and 2y
            origin = m[:3, :3] @ np.array([-1.0, -1.0, 0.0]) + m[:3, 3]
            rect = Rectangle(origin, m[:3, :3] @ np.array([2.0, 0, 0]), m[:3, :3] @ np.array([0, 2.0, 0]))
            scene.add(rect, obj["material"], name=obj["name"])
        elif obj["shape"] == "sphere":
            scene.add(Sphere(obj["center"], obj["radius"]), obj["material"], name=obj["name"])
        elif obj["shape"] == "triangle_mesh":
            mesh = TriangleMesh.from_arrays(vertices, faces, name="blob")
            scene.add(mesh, obj["material"], transform=np.asarray(obj["to_world"], dtype=np.float64), name=obj["name"])
        else:
            raise SceneError(f"peer scene: unknown shape {obj['shape']!r}")
    return scene


def variance_file(reference: str | Path) -> Path:
    """Where the variance of ``reference``'s mean lives: ``NAME_var.exr`` beside ``NAME.exr``, as the kit's
    ``render.py --variance-out`` writes it."""
    reference = Path(reference)
    return reference.with_name(reference.stem + "_var.exr")


def reference_noise(reference: str | Path) -> np.ndarray | None:
    """The reference's own noise in the relMSE, per pixel and channel, (H, W, 3): var / (ref^2 + 0.01), var the
    variance of its mean, from ``NAME_var.exr`` beside ``NAME.exr`` as the kit's ``render.py --variance-out`` writes
    it; None without that file."""
    from .analysis.metrics import RELMSE_EPSILON
    from .images import read_image

    variance = variance_file(reference)
    if not variance.exists():
        return None
    ref = read_image(str(reference))[:, :, :3]
    return read_image(str(variance))[:, :, :3] / (ref**2 + RELMSE_EPSILON)


def reference_floor(reference: str | Path) -> float | None:
    """The part of every relMSE against ``reference`` that is the reference's own noise (the peer kit's
    ``ref_floor``): the mean of :func:`reference_noise` over pixels and channels, or None without the variance."""
    noise = reference_noise(reference)
    return None if noise is None else float(np.mean(noise))
