"""Analysis: chi-square tests of samplers, error metrics, convergence studies."""

from . import chi2

__all__ = ["chi2"]
