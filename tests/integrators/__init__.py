"""Tests of the integrators (shading-point estimators and the wavefront renderer)."""

from lightprobe.integrators.shading_point import STRATEGIES

# Every strategy with the balance heuristic, and MIS with the power heuristic too.
STRATEGY_CASES = [(strategy, "balance") for strategy in STRATEGIES] + [("mis", "power")]
