"""lightprobe: a statistically verified Monte Carlo renderer for image-based lighting.

The public API (see the README and each module's docstring):

* lights: :class:`EnvironmentMap` (``load``, ``from_array``, ``eval``, ``sample``, ``pdf``);
* materials: :class:`Lambert`, :class:`Phong`, :class:`GGXConductor` (``eval``, ``sample``, ``pdf``);
* estimators at one shading point: :func:`estimate`;
* sampling building blocks: :mod:`lightprobe.sampling` (warps, distributions, MIS heuristics);
* verification: :mod:`lightprobe.analysis.chi2`.
"""

from .bsdfs import BSDF, GGXConductor, Lambert, Phong
from .emitters.envmap import EnvironmentMap
from .errors import ImageError, LightprobeError, LightprobeWarning, ParameterError, SceneError
from .integrators.shading_point import Estimate, estimate

__version__ = "0.1.0"

__all__ = [
    "BSDF",
    "EnvironmentMap",
    "Estimate",
    "GGXConductor",
    "ImageError",
    "Lambert",
    "LightprobeError",
    "LightprobeWarning",
    "ParameterError",
    "Phong",
    "SceneError",
    "__version__",
    "estimate",
]
