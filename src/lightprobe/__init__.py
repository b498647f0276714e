"""lightprobe: a statistically verified Monte Carlo renderer for image-based lighting.

The public API (see the README and each module's docstring):

* lights: :class:`EnvironmentMap` (``load``, ``from_array``, ``eval``, ``sample``, ``pdf``), :class:`PointLight`,
  :class:`SpotLight` (``Scene.add_light``; area lights are objects with an emission);
* materials: :class:`Lambert`, :class:`Phong`, :class:`GGXConductor`, :class:`RoughPlastic`,
  :class:`MetallicRoughness` (``eval``, ``sample``, ``pdf``); textures: :class:`ImageTexture`,
  :class:`MaterialTextures` (the ``textures=`` of a Lambert or metallic-roughness material);
* estimators at one shading point: :func:`estimate`;
* scenes and rendering: :class:`Scene`, :class:`Camera`, :class:`TriangleMesh`, :class:`Sphere`,
  :class:`Rectangle`, :func:`render` with :class:`RenderSettings`;
* sampling building blocks: :mod:`lightprobe.sampling` (warps, distributions, MIS heuristics);
* verification: :mod:`lightprobe.analysis.chi2`.
"""

from .bsdfs import BSDF, GGXConductor, Lambert, MetallicRoughness, Phong, RoughPlastic
from .emitters.envmap import EnvironmentMap
from .emitters.punctual import PointLight, SpotLight
from .errors import ImageError, LightprobeError, LightprobeWarning, ParameterError, SceneError
from .geometry import Camera, Rectangle, Sphere, TriangleMesh
from .integrators import Estimate, RenderResult, RenderSettings, estimate, render
from .scene import Scene
from .textures import ImageTexture, MaterialTextures

__version__ = "0.1.0"

__all__ = [
    "BSDF",
    "Camera",
    "EnvironmentMap",
    "Estimate",
    "GGXConductor",
    "ImageError",
    "ImageTexture",
    "Lambert",
    "LightprobeError",
    "LightprobeWarning",
    "MaterialTextures",
    "MetallicRoughness",
    "ParameterError",
    "Phong",
    "PointLight",
    "Rectangle",
    "RenderResult",
    "RenderSettings",
    "RoughPlastic",
    "Scene",
    "SceneError",
    "Sphere",
    "SpotLight",
    "TriangleMesh",
    "__version__",
    "estimate",
    "render",
]
