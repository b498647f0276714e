"""Integrators: estimators at one shading point, and the wavefront renderer."""

from .shading_point import Estimate, estimate
from .wavefront import RenderResult, RenderSettings, render

__all__ = ["Estimate", "RenderResult", "RenderSettings", "estimate", "render"]
