"""Sampling: warps (sample / pdf / invert triples), piecewise-constant distributions, MIS heuristics."""

from . import kernels, warps
from .distributions import PiecewiseConstant1D, PiecewiseConstant2D
from .mis import balance_heuristic, power_heuristic

__all__ = [
    "PiecewiseConstant1D",
    "PiecewiseConstant2D",
    "balance_heuristic",
    "kernels",
    "power_heuristic",
    "warps",
]
