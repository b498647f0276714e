"""Monte Carlo estimators of the illumination integral at one shading point (the seed's exact setting).

At a fixed point with normal ``normal``, seen from ``wo`` (world, toward the viewer), estimate Krivanek eq. 2::

    L_o = integral over the sphere of L(w) V(w) f(wo, w) cos(theta) dw

with one of the strategies

============  =====================================================================================================
``uniform``   directions uniform on the hemisphere about the normal (pdf 1/(2 pi))
``cosine``    cosine-weighted hemisphere (pdf cos/pi)
``brdf``      BSDF importance sampling (the material's own ``sample``)
``env``       environment-map importance sampling
``mis``       ``n_bsdf`` BSDF samples and ``n_env`` environment samples combined with the balance or power
              heuristic (Krivanek eqs. 16-18, Veach's one-sample-per-technique-count weights)
============  =====================================================================================================

Every estimate is built from ``n`` independent *groups*; a group is one direction for the single-technique
strategies and ``n_bsdf + n_env`` directions for MIS.  The result reports the mean, the sample variance of one
group, and the variance of the mean, so estimators can be compared at equal numbers of directions (see
:meth:`Estimate.variance_per_sample`).  ``visibility`` (a function of world directions returning 0/1) stands in
for shadow rays; by default nothing is blocked.  The estimator is the laboratory's
(:func:`lightprobe.integrators.batch_estimator.shade`): the n groups are n copies of the point, each with its own
directions, so a change to the estimator is made in one place.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..bsdfs.base import BSDF
from ..bsdfs.phong import Phong
from ..color import luminance
from ..emitters.envmap import EnvironmentMap
from ..errors import ParameterError
from ..geometry.frame import frame_matrix
from ..sampling.mis import balance_heuristic, power_heuristic
from .batch_estimator import Context, EnvironmentSampling, HemisphereSampling, MaterialSampling, shade

__all__ = ["STRATEGIES", "Estimate", "estimate"]

STRATEGIES = ("uniform", "cosine", "brdf", "env", "mis")
HEURISTICS = ("balance", "power")
#: the single-technique strategies' techniques
TECHNIQUES = {
    "uniform": lambda: HemisphereSampling(cosine=False),
    "cosine": lambda: HemisphereSampling(cosine=True),
    "brdf": MaterialSampling,
    "env": EnvironmentSampling,
}


@dataclass(frozen=True)
class Estimate:
    """Result of :func:`estimate`: RGB mean, per-group variances, and bookkeeping."""

    mean: np.ndarray  # (3,)
    group_variance: np.ndarray  # (3,) sample variance of one group's value, per channel
    luminance_group_variance: float  # sample variance of the luminance of one group's value
    n_groups: int
    samples_per_group: int
    strategy: str

    @property
    def variance(self) -> np.ndarray:
        """Variance of the mean (3,)."""
        return self.group_variance / self.n_groups

    @property
    def std_error(self) -> np.ndarray:
        return np.sqrt(self.variance)

    @property
    def n_samples(self) -> int:
        """Directions drawn in total."""
        return self.n_groups * self.samples_per_group

    def variance_per_sample(self) -> np.ndarray:
        """Group variance x directions per group: the variance of a one-direction budget, comparable across
        strategies (an estimator from N directions has variance ``variance_per_sample() / N``)."""
        return self.group_variance * self.samples_per_group

    def relative_variance_per_sample(self) -> float:
        """Luminance variance per direction divided by the squared luminance of the mean (dimensionless)."""
        m = float(luminance(self.mean))
        return self.luminance_group_variance * self.samples_per_group / (m * m) if m > 0 else float("nan")


def _unit(v, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    n = np.linalg.norm(a)
    if a.size != 3 or not np.isfinite(n) or n == 0:
        raise ParameterError(f"{name} must be a non-zero 3-vector, got {v!r}")
    return a / n


def _mis_weight(heuristic: str, n_f: int, p_f, n_g: int, p_g):
    if heuristic == "balance":
        return balance_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)
    return power_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)


def estimate(
    env: EnvironmentMap,
    bsdf: BSDF,
    *,
    strategy: str = "mis",
    n: int = 10_000,
    normal=(0.0, 1.0, 0.0),
    wo=(0.0, 0.70710678, 0.70710678),
    heuristic: str = "balance",
    n_bsdf: int = 1,
    n_env: int = 1,
    compensated: bool = False,
    seed: int = 0,
    visibility: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Estimate:
    """Estimate the reflected radiance L_o at one shading point.  See the module docstring.

    Parameters
    ----------
    env, bsdf
        The light and the material.
    strategy : {"uniform", "cosine", "brdf", "env", "mis"}
    n : int
        Number of groups (directions for single techniques; ``n_bsdf + n_env`` directions each for MIS).
    normal, wo : 3-vectors
        Surface normal and direction toward the viewer, world space.
    heuristic : {"balance", "power"}
        MIS weighting (power uses beta = 2).
    n_bsdf, n_env : int
        Samples per group from each technique (MIS only).
    compensated : bool
        Sample the environment from its MIS-compensated PDF (MIS only; it is zero on dim texels).
    seed : int
        Seed of the random numbers (results are reproducible bit for bit).
    visibility : callable, optional
        ``visibility(dirs) -> (N,)`` with 1 where the world direction is unblocked, 0 where it is blocked.
    """
    if strategy not in STRATEGIES:
        raise ParameterError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
    if heuristic not in HEURISTICS:
        raise ParameterError(f"heuristic must be one of {HEURISTICS}, got {heuristic!r}")
    n = int(n)
    if n < 2:
        raise ParameterError(f"n must be >= 2 (a variance needs two groups), got {n}")
    if strategy != "mis" and compensated:
        raise ParameterError("compensated=True is only valid with strategy='mis' (the PDF is zero on dim texels)")
    if strategy == "mis":
        if n_bsdf < 0 or n_env < 0 or n_bsdf + n_env == 0:
            raise ParameterError(f"n_bsdf and n_env must be >= 0 and not both 0, got {n_bsdf}, {n_env}")
        if isinstance(bsdf, Phong) and bsdf.estimator != "mixture":
            raise ParameterError(
                "MIS needs the BSDF's full mixture pdf (seed eq. 19); use Phong(..., estimator='mixture')"
            )
    if strategy == "brdf" and isinstance(bsdf, Phong) and bsdf.estimator != "mixture":
        raise ParameterError(
            "this estimator weighs a sample by f cos / p of the whole BSDF; Phong's chosen_lobe estimator (seed "
            "section 2.4) is the render core's: render with strategy='brdf'"
        )
    nrm = _unit(normal, "normal")
    frame = frame_matrix(nrm)  # rows s, t, n: local = frame @ world
    ctx = Context.at_point(frame @ _unit(wo, "wo"), frame, n, bsdf, env)
    if strategy == "mis":
        techniques, counts = (MaterialSampling(), EnvironmentSampling(compensated)), (n_bsdf, n_env)
        techniques, counts = zip(*[(t, c) for t, c in zip(techniques, counts, strict=True) if c > 0], strict=True)
    else:
        techniques, counts = (TECHNIQUES[strategy](),), (1,)
    rng = np.random.default_rng(seed)
    numbers = [rng.random((count, n, t.dimensions)) for t, count in zip(techniques, counts, strict=True)]

    def occluded(origins, dirs):
        if visibility is None:
            return np.zeros(dirs.shape[0], dtype=np.bool_)
        seen = np.asarray(visibility(dirs))
        if seen.shape not in ((dirs.shape[0],), (dirs.shape[0], 1)):
            raise ParameterError(
                f"visibility(dirs) must return one value per direction ({dirs.shape[0]},), got shape {seen.shape}"
            )
        return seen.reshape(-1) == 0

    def weight(n_f, p_f, n_g, p_g):
        return _mis_weight(heuristic, n_f, p_f, n_g, p_g)

    values, _ = shade(ctx, techniques, counts, weight, numbers, np.tile(nrm, (n, 1)), np.zeros(n), occluded)
    samples_per_group = sum(counts)

    if not np.all(np.isfinite(values)):
        raise RuntimeError(f"non-finite sample values in strategy {strategy!r}: this is a bug in lightprobe")
    return Estimate(
        mean=values.mean(axis=0),
        group_variance=values.var(axis=0, ddof=1),
        luminance_group_variance=float(np.var(luminance(values), ddof=1)),
        n_groups=n,
        samples_per_group=samples_per_group,
        strategy=strategy,
    )
