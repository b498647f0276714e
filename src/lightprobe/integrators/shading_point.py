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
for shadow rays; by default nothing is blocked.
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
from ..sampling import warps
from ..sampling.mis import balance_heuristic, power_heuristic

__all__ = ["STRATEGIES", "Estimate", "estimate"]

STRATEGIES = ("uniform", "cosine", "brdf", "env", "mis")
HEURISTICS = ("balance", "power")


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
        ``visibility(dirs) -> (N,)`` with 1 where the world direction is unblocked.
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
    nrm = _unit(normal, "normal")
    frame = frame_matrix(nrm)  # rows s, t, n: local = frame @ world
    wo_local = frame @ _unit(wo, "wo")
    rng = np.random.default_rng(seed)

    def shade_local(wi_local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World directions and L(w) V(w) for local directions."""
        world = wi_local @ frame
        radiance = env.eval(world)
        if visibility is not None:
            radiance = radiance * np.asarray(visibility(world), dtype=np.float64).reshape(-1, 1)
        return world, radiance

    if strategy in ("uniform", "cosine"):
        u = rng.random((n, 2))
        if strategy == "uniform":
            wi = warps.square_to_uniform_hemisphere(u)
            pdf = warps.uniform_hemisphere_pdf(wi)
        else:
            wi = warps.square_to_cosine_hemisphere(u)
            pdf = warps.cosine_hemisphere_pdf(wi)
        _, radiance = shade_local(wi)
        f = bsdf.eval(wo_local, wi)
        with np.errstate(divide="ignore", invalid="ignore"):
            values = np.where((pdf > 0)[:, None], f * wi[:, 2:3] * radiance / pdf[:, None], 0.0)
        samples_per_group = 1
    elif strategy == "brdf":
        wi, pdf, weight = bsdf.sample_weight(wo_local, rng.random((n, 3)))
        _, radiance = shade_local(wi)
        values = weight * radiance
        samples_per_group = 1
    elif strategy == "env":
        world, pdf = env.sample(rng.random((n, 2)))
        values = _env_contributions(env, bsdf, frame, wo_local, world, pdf, visibility)
        samples_per_group = 1
    else:
        values = np.zeros((n, 3))
        if n_bsdf:
            u = rng.random((n * n_bsdf, 3))
            wi, p_b, weight = bsdf.sample_weight(wo_local, u)
            world, radiance = shade_local(wi)
            p_e = env.pdf(world, compensated=compensated)
            w = _mis_weight(heuristic, n_bsdf, p_b, n_env, p_e)
            values += (weight * radiance * w[:, None]).reshape(n, n_bsdf, 3).sum(axis=1) / n_bsdf
        if n_env:
            world, p_e = env.sample(rng.random((n * n_env, 2)), compensated=compensated)
            wi = world @ frame.T
            p_b = bsdf.pdf(wo_local, wi)
            w = _mis_weight(heuristic, n_env, p_e, n_bsdf, p_b)
            contrib = _env_contributions(env, bsdf, frame, wo_local, world, p_e, visibility) * w[:, None]
            values += contrib.reshape(n, n_env, 3).sum(axis=1) / n_env
        samples_per_group = n_bsdf + n_env

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


def _env_contributions(env, bsdf, frame, wo_local, world, pdf, visibility) -> np.ndarray:
    """f(wo, wi) cos(theta_i) L(wi) V(wi) / p_env(wi) for environment-sampled world directions."""
    wi = world @ frame.T
    f = bsdf.eval(wo_local, wi)
    radiance = env.eval(world)
    if visibility is not None:
        radiance = radiance * np.asarray(visibility(world), dtype=np.float64).reshape(-1, 1)
    cos = np.maximum(wi[:, 2:3], 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((pdf > 0)[:, None], f * cos * radiance / pdf[:, None], 0.0)
