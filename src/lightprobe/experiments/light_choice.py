"""The choice of light at the camera's shading points: how far each light selector is from the best possible one
(the oracle), and where a render's variance comes from (the choice of light, the point on it, visibility, the BSDF
sample, the pixel).

At ``points`` camera samples (``PER_PIXEL`` jittered ones in each of a stratified sample of the pixels: half from the
edges, weighted back to the image), every light's contribution to each first hit is estimated by brute force:
``per_light`` stratified samples on each light (the renderer's own light sampling,
``emitters.lights.light_sample_of``), each with its shadow ray, and ``bsdf_samples`` BSDF directions with the rays
they trace.  For light l with selection probability P_l, the light-sample estimator of one sample is X = w g V / P_l,
with g = f L cos / p (luminance; p the density of the point on the light), V the shadow ray's verdict and w the
strategy's MIS weight.  Its variance splits exactly by the law of total variance::

    Var X = [sum_l m_l^2 / P_l - (sum_l m_l)^2]                   the choice of light      (m_l = E[w g V | l])
          + sum_l c_l^2 Var(w g | l) / P_l                         the point on the light   (c_l = m_l / E[w g | l])
          + sum_l (Var(w g V | l) - c_l^2 Var(w g | l)) / P_l      visibility

the point term being what the variance would be if each light's shadows were spread evenly over it (a light that
is half hidden counts as a light of half the brightness); visibility is what the shadows' unevenness adds (it can
be slightly negative where a shadow happens to hide the part of a light the sampling over-weights).  The BSDF
sample's variance is the fourth term.  A camera sample of ``n_light`` light samples and ``n_bsdf`` BSDF samples has
variance Var X / n_light + Var B / n_bsdf (independent samples: the renderer's Sobol' points do better); the fifth,
the pixel's, is the spread of what a pixel's camera samples see and their direct light (less the brute force's own
noise).  Each term is reported as its share of a 1-spp relMSE: the image's mean of variance / (mean^2 + 0.01).

For the selectors (light sampling alone, no MIS weight), the table gives the variance the choice adds and the whole
light-sample variance relative to the **oracle**, P_l proportional to m_l: what a selector that knew every light's
contribution, visibility included, would pick; its choice adds nothing.  The **unoccluded oracle** (P_l
proportional to E[g | l], shadows ignored) is the best a selector blind to visibility can do.  The
**variance-optimal** selector, P_l proportional to sqrt(E[(g V)^2 | l]), minimises the whole
sum_l E[(g V)^2 | l] / P_l (Cauchy-Schwarz): below the oracle where lights differ in how unevenly they light the
point.  A user's selector (:mod:`lightprobe.lab.selectors`) joins the table.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..analysis.metrics import RELMSE_EPSILON
from ..color import LUMINANCE_WEIGHTS
from ..emitters.area import STRATEGIES as LIGHT_STRATEGIES
from ..emitters.kinds import flag_rows
from ..emitters.selection import _pmf_all, build_selector
from ..errors import ParameterError
from ..geometry.raytracer import RayTracer
from ..integrators.light_learning import cells_learned, restored
from ..integrators.settings import RenderSettings
from ..integrators.wavefront import _compensated_materials, compensation_for, resolve
from ..lab.camera_samples import camera_batch, shading_batch
from ..lab.light_render import bsdf_rays, light_sample_rows, quiet_compiling, what_rays_see
from ..lab.selectors import PICK_POINTS, PICKS
from ..sampling.mis import balance_heuristic, power_heuristic
from ..scene import Scene

__all__ = [
    "RAY_BUDGET",
    "SELECTOR_CHECKS",
    "LightChoice",
    "SelectorRow",
    "Split",
    "check_selector",
    "check_selectors",
    "measure",
    "selector_test_scene",
]

#: light samples (each with its shadow ray) the brute force may take: points x lights x per_light
RAY_BUDGET = 1 << 22
#: fewer points than this say too little: a scene with more lights is not measured
MIN_POINTS = 16
#: camera samples per measured pixel (where in the pixel a sample lands is the split's fifth term)
PER_PIXEL = 4
#: rays through each pixel (a regular grid) that find the edges: pixels where they meet more than one surface
EDGE_TRIALS = 16
#: pixels classified as edge or not at most (a random subset of a larger image)
EDGE_PIXELS = 1 << 16
#: the selectors of the renderer that every table lists (the strategies' own are added)
BUILTIN_SELECTORS = ("uniform", "power", "bvh")
#: the strategies whose variance is split: light samples, BSDF samples, or both under MIS
SPLIT_STRATEGIES = ("mis", "env", "brdf")


@dataclass
class SelectorRow:
    """One selector's light-sample variance at the points, as a 1-spp relMSE (light sampling alone)."""

    name: str
    #: what the choice of light adds
    choice: float
    #: choice, point on the light and visibility: the light-sample estimator's whole variance
    total: float
    #: ``total`` over the oracle's: how many times the oracle's samples this selector needs for its error
    vs_oracle: float


@dataclass
class Split:
    """Where one strategy's variance comes from, each term its share of a 1-spp relMSE (independent samples)."""

    label: str
    selector: str
    choice: float
    point: float
    visibility: float
    bsdf: float
    #: where in the pixel the camera sample lands (edges, emitters and the background seen directly), measured
    #: without the outline control variate, which takes part of it away where an emitter's outline crosses a pixel
    pixel: float = 0.0

    @property
    def total(self) -> float:
        return self.choice + self.point + self.visibility + self.bsdf + self.pixel


@dataclass
class LightChoice:
    """What :func:`measure` found; ``skipped`` says why nothing was measured (``selectors`` and ``splits`` empty)."""

    points: int
    lights: int
    per_light: int
    bsdf_samples: int
    #: the share of the lights' unoccluded contribution that reaches the points (visibility's toll)
    arriving: float = math.nan
    selectors: list[SelectorRow] = field(default_factory=list)
    splits: list[Split] = field(default_factory=list)
    #: strategies whose variance is not split (hemisphere sampling, a laboratory technique), with the reason
    unsplit: dict[str, str] = field(default_factory=dict)
    #: pixels left out because a camera sample there met a textured material (its BSDF here would be the untextured
    #: one)
    textured: int = 0
    seconds: float = 0.0
    skipped: str | None = None
    #: per strategy label, the variance of one camera sample that its render measured (relMSE; compare fills it)
    measured: dict[str, float] = field(default_factory=dict)
    #: with ``measure(..., keep_tables=True)``: the light samples of the selectors' table (``g``, ``seen``: (points,
    #: lights, samples) of lum(f L cos) / p and the shadow rays' verdicts), every selector's pmf (points, lights) and
    #: the points' weights, for experiments beyond the report (benchmarks/selection_oracle.py)
    tables: dict | None = field(default=None, repr=False)


# --- shading points -------------------------------------------------------------------------------------------------
@dataclass
class _Points:
    point: np.ndarray
    gnormal: np.ndarray
    error: np.ndarray
    frame: np.ndarray  # (N, 9): s, t, n
    wo: np.ndarray  # local
    material: np.ndarray


@dataclass
class _CameraSamples:
    """``PER_PIXEL`` camera samples in each measured pixel, a pixel's consecutive."""

    weight: np.ndarray  # (pixels,) each measured pixel's weight in a mean over the image (they sum to 1)
    seen: np.ndarray  # (S,) luminance of what it sees directly
    shaded: np.ndarray  # (S,) its row in the points, or -1 (nothing to shade)
    points: _Points
    textured: int  # pixels left out: a camera sample there met a textured material

    def point_weights(self) -> np.ndarray:
        """Each point's weight in a mean over the image's shaded camera samples."""
        w = np.repeat(self.weight, PER_PIXEL)[self.shaded >= 0]
        return w / w.sum()


def _first_hits(scene, arrays, lights, env, tracer, pixels, jitter):
    """Camera rays through ``pixels`` (``jitter`` in [0, 1)^2), their first hits and the luminance of what each sees
    itself: an emitter's radiance, or the infinite lights' where it leaves the scene (integrators/stages/setup.py)."""
    dirs = camera_batch(scene.camera.kernel_array(), pixels, jitter)
    origin = np.asarray(scene.camera.origin, dtype=np.float64)
    origins = np.ascontiguousarray(np.broadcast_to(origin, dirs.shape))
    hits = tracer.intersect(origins, dirs)
    at_camera = (origin[None, :], origin[None, :], np.zeros(1, np.bool_), np.zeros(dirs.shape[0], np.int64))
    seen = what_rays_see(arrays, lights, env, 0, *at_camera, origins, dirs, np.ones_like(dirs), hits)[1].sum(axis=1)
    return hits, origin, dirs, seen


def _cell_centres(side: int) -> np.ndarray:
    """The centres of a side x side grid's cells in [0, 1)^2, (side^2, 2)."""
    cells = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2)
    return (cells + 0.5) / side


def _stratified_pixels(scene: Scene, arrays, lights, env, tracer: RayTracer, n_pixels: int, rng):
    """(pixels, their weights in a mean over the image) of ``n_pixels`` pixels drawn in two strata (a stratified
    sample of the image, weighted to stay unbiased): pixels whose ``EDGE_TRIALS`` grid rays meet more than one
    surface, or see different emitted light (edges: few, where the spread within a pixel is), get half of them; the
    rest, the other half.  An image of more than ``EDGE_PIXELS`` pixels is classified at that many random ones (the
    strata's sizes scaled up from them)."""
    width, height = scene.camera.resolution
    n_image = width * height
    tried = np.arange(n_image, dtype=np.int64)
    if n_image > EDGE_PIXELS:
        tried = np.sort(rng.choice(n_image, EDGE_PIXELS, replace=False)).astype(np.int64)
    every = np.repeat(tried, EDGE_TRIALS)
    cells = _cell_centres(int(math.sqrt(EDGE_TRIALS)))
    hits, _, _, seen = _first_hits(scene, arrays, lights, env, tracer, every, np.tile(cells, (tried.size, 1)))
    surface_id = (hits[1].astype(np.int64) * (1 << 40) + hits[2].astype(np.int64)).reshape(-1, EDGE_TRIALS)
    seen = seen.reshape(-1, EDGE_TRIALS)
    edge = (surface_id != surface_id[:, :1]).any(axis=1) | (
        np.abs(seen - seen[:, :1]) > 1e-3 * (np.abs(seen[:, :1]) + 1e-3)
    ).any(axis=1)
    strata = [tried[edge], tried[~edge]]
    wanted = min(strata[0].size, n_pixels // 2)
    wanted = [wanted, min(strata[1].size, n_pixels - wanted)]
    chosen, weight = [], []
    for members, count in zip(strata, wanted, strict=True):
        if count:  # each chosen pixel stands for its stratum's share of the image over the pixels chosen from it
            chosen.append(rng.choice(members, count, replace=False))
            weight.append(np.full(count, members.size / count / tried.size))
    return np.concatenate(chosen), np.concatenate(weight)


def _camera_samples(scene: Scene, arrays, lights, env, tracer: RayTracer, chosen, weight, rng) -> _CameraSamples:
    """``PER_PIXEL`` camera samples (jittered) in each pixel of ``chosen`` (``weight``: the pixels' weights), and
    their first hits' shading points.  Pixels where a sample meets a textured material are left out (its BSDF here
    would be the untextured one)."""
    pixels = np.repeat(chosen, PER_PIXEL)
    hits, origin, dirs, seen = _first_hits(scene, arrays, lights, env, tracer, pixels, rng.random((pixels.size, 2)))
    t, kind, index, prim, b1, b2 = hits
    point, gnormal, error, frame, wo, material = shading_batch(arrays, kind, index, prim, b1, b2, t, origin, dirs)
    shaded = (material >= 0) & (wo[:, 2] > 0.0)
    textured = (shaded & (arrays.material_textured[np.maximum(material, 0)] != 0)).reshape(-1, PER_PIXEL).any(axis=1)
    keep = np.flatnonzero(~textured)
    rows = (keep[:, None] * PER_PIXEL + np.arange(PER_PIXEL)).reshape(-1)
    rows_shaded = rows[shaded[rows]]
    index_of = np.full(rows.size, -1, np.int64)
    index_of[shaded[rows]] = np.arange(rows_shaded.size)
    points = _Points(
        point[rows_shaded], gnormal[rows_shaded], error[rows_shaded], frame[rows_shaded], wo[rows_shaded],
        material[rows_shaded],
    )  # fmt: skip
    kept = weight[keep]
    return _CameraSamples(kept / max(kept.sum(), 1e-300), seen[rows], index_of, points, int(textured.sum()))


# --- light samples --------------------------------------------------------------------------------------------------
@dataclass
class _LightTerms:
    g: np.ndarray  # (P, L, K) lum(f L cos) / p, unshadowed
    pdf: np.ndarray  # (P, L, K) the point's density on the light
    pb: np.ndarray  # (P, L, K) the BSDF's density at the direction
    seen: np.ndarray  # (P, L, K) bool: the shadow ray arrives


def _light_terms(arrays, lights, env, tracer, pts: _Points, compensated, strategy: str, per_light, rng) -> _LightTerms:
    """Every light's ``per_light`` samples (a jittered grid) at every point, with their shadow rays, a chunk of points
    at a time (the rays' records stay under ~40 MB)."""
    n_points, n_lights = pts.point.shape[0], lights.kind.shape[0]
    side = round(math.sqrt(per_light))
    grid = _cell_centres(side)
    shape = (n_points, n_lights, per_light)
    g, pdf, pb = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    seen = np.zeros(shape, np.bool_)
    chunk = max(1, (1 << 19) // (n_lights * per_light))
    for lo in range(0, n_points, chunk):
        hi = min(n_points, lo + chunk)
        rows = (hi - lo) * n_lights * per_light
        u = (np.tile(grid, ((hi - lo) * n_lights, 1)) + (rng.random((rows, 2)) - 0.5) / side) % 1.0
        # row r = (point i, light l, sample j), i-major
        owner = np.arange(rows, dtype=np.int64) // (n_lights * per_light)
        light = (np.arange(rows, dtype=np.int64) // per_light) % n_lights
        rgb, p, p_bsdf, ray = np.empty((rows, 3)), np.empty(rows), np.empty(rows), np.empty((rows, 7))
        light_sample_rows(
            lights, env, LIGHT_STRATEGIES[strategy], pts.point[lo:hi], pts.gnormal[lo:hi], pts.error[lo:hi],
            pts.frame[lo:hi], pts.wo[lo:hi], arrays.material_kind, arrays.material_params, pts.material[lo:hi],
            np.ascontiguousarray(compensated[lo:hi]), owner, light, u, rgb, p, p_bsdf, ray,
        )  # fmt: skip
        out = np.stack([rgb @ LUMINANCE_WEIGHTS, p, p_bsdf], axis=1)  # g = lum(f L cos) / p, p, the BSDF's pdf
        arrives = out[:, 0] > 0.0
        live = np.flatnonzero(arrives)
        if live.size:
            arrives[live] = ~tracer.occluded(ray[live, 0:3], ray[live, 3:6], ray[live, 6])
        part = (hi - lo, n_lights, per_light)
        g[lo:hi], pdf[lo:hi], pb[lo:hi] = out[:, 0].reshape(part), out[:, 1].reshape(part), out[:, 2].reshape(part)
        seen[lo:hi] = arrives.reshape(part)
    return _LightTerms(g, pdf, pb, seen)


# --- BSDF samples ---------------------------------------------------------------------------------------------------
@dataclass
class _BsdfTerms:
    owner: np.ndarray  # (R,) the point of each entry
    pb: np.ndarray  # (R,) the BSDF's density of the direction
    light: np.ndarray  # (R, E) the light reached (-1: none)
    value: np.ndarray  # (R, E) lum(f cos / pb L)
    light_pdf: np.ndarray  # (R, E)


def _bsdf_terms(arrays, lights, env, tracer, pts: _Points, compensated, strategy: str, count: int, rng) -> _BsdfTerms:
    n_points = pts.point.shape[0]
    owner = np.repeat(np.arange(n_points), count)
    u = rng.random((owner.size, 3))
    pb, weight, keep, o, d = bsdf_rays(arrays, pts.point, pts.gnormal, pts.error, pts.frame, pts.wo, pts.material,
                                       owner, u)  # fmt: skip
    n_entries = max(1, int(flag_rows(lights.kind, "infinite").sum()))
    light_of = np.full((owner.size, n_entries), -1, np.int64)
    value = np.zeros((owner.size, n_entries))
    light_pdf = np.zeros((owner.size, n_entries))
    if keep.size:
        light_of[keep], value[keep], light_pdf[keep] = what_rays_see(
            arrays, lights, env, LIGHT_STRATEGIES[strategy], pts.point, pts.gnormal, compensated, owner[keep], o, d,
            np.ascontiguousarray(weight[keep]), tracer.intersect(o, d),
        )[:3]  # fmt: skip
    return _BsdfTerms(owner, pb, light_of, value, light_pdf)


# --- the split ------------------------------------------------------------------------------------------------------
def _light_moments(terms: _LightTerms, weight: np.ndarray | None):
    """Per point and light: m = E[a V], u = E[a], s2 = E[(a V)^2], q2 = E[a^2], a = w g (the sample's value times
    its selection probability)."""
    a = terms.g if weight is None else terms.g * weight
    av = np.where(terms.seen, a, 0.0)
    return av.mean(axis=2), a.mean(axis=2), (av * av).mean(axis=2), (a * a).mean(axis=2)


def _light_variance(moments, pmf: np.ndarray):
    """Per point: (mean, choice, point, visibility) of the one-sample light estimator with selection ``pmf``."""
    m, u, s2, q2 = moments
    picked = pmf > 0.0
    inv = np.where(picked, 1.0 / np.where(picked, pmf, 1.0), 0.0)
    mean = np.where(picked, m, 0.0).sum(axis=1)  # a light never picked gives nothing (its MIS weight is 0)
    choice = (m * m * inv).sum(axis=1) - mean * mean
    c = np.where(u > 0.0, m / np.where(u > 0.0, u, 1.0), 0.0)
    point = (c * c * np.maximum(q2 - u * u, 0.0) * inv).sum(axis=1)
    within = ((s2 - m * m) * inv).sum(axis=1)
    return mean, np.maximum(choice, 0.0), point, within - point


def _bsdf_values(terms: _BsdfTerms, n_points: int, pmf, n_light, n_bsdf, beta):
    """Per BSDF sample, its MIS-weighted value (``pmf`` None: BSDF sampling alone, weight 1)."""
    value = terms.value.copy()
    if pmf is not None:
        for e in range(value.shape[1]):
            rows = np.flatnonzero(terms.light[:, e] >= 0)
            p_light = pmf[terms.owner[rows], terms.light[rows, e]] * terms.light_pdf[rows, e]
            value[rows, e] *= _mis(n_bsdf, terms.pb[rows], n_light, p_light, beta)
    return value.sum(axis=1).reshape(n_points, -1)


def _mis(n_f, p_f, n_g, p_g, beta) -> np.ndarray:
    """The renderer's MIS weight (sampling/mis.py) of samples of technique f against g."""
    if beta == 1.0:
        return balance_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)
    return power_heuristic(p_f, p_g, n_f=n_f, n_g=n_g, beta=beta)


def _light_weights(terms: _LightTerms, pmf: np.ndarray, n_light, n_bsdf, beta) -> np.ndarray:
    return _mis(n_light, pmf[:, :, None] * terms.pdf, n_bsdf, terms.pb, beta)


def _relative(variance: np.ndarray, mean: np.ndarray, weight: np.ndarray) -> float:
    """The weighted mean of variance / (mean^2 + RELMSE_EPSILON): a relMSE's terms."""
    return float(np.sum(weight * variance / (mean * mean + RELMSE_EPSILON)))


def _selector_pmf(selector, pts: _Points, compensated) -> np.ndarray:
    return np.stack(
        [_pmf_all(selector, pts.point[i], pts.gnormal[i], bool(compensated[i])) for i in range(pts.point.shape[0])]
    )


def measure(
    scene: Scene,
    strategies: list[tuple[str, RenderSettings, dict | None]],
    *,
    points: int = 512,
    per_light: int | None = None,
    bsdf_samples: int = 64,
    seed: int = 11,
    user_selectors=(),
    keep_tables: bool = False,
) -> LightChoice | None:
    """The oracle table and each strategy's split (``strategies``: (label, settings, the learned table of its
    render or None)), at ``points`` camera samples (``PER_PIXEL`` in each pixel measured); None for a scene with
    fewer than two lights (an environment map's own sampling is the laboratory's ``check`` and shading-point
    experiment).  ``user_selectors``: :class:`lightprobe.lab.selectors.GuardedSelector` s.  ``per_light``, a square
    number: samples of each light at each point (default: the most of 16 .. 256 that ``RAY_BUDGET`` allows; a light's
    variance over its points is heavy-tailed where a glossy lobe meets a broad light, and few samples underestimate
    it)."""
    with quiet_compiling():
        return _measure(scene, strategies, points, per_light, bsdf_samples, seed, user_selectors, keep_tables)


def _measure(scene, strategies, points, per_light, bsdf_samples, seed, user_selectors, keep_tables):
    start = time.perf_counter()
    lights = scene.light_table()
    n_lights = lights.kind.shape[0]
    if n_lights < 2:
        return None
    if per_light is None:
        side = int(math.sqrt(RAY_BUDGET / max(points, 1) / n_lights))
        per_light = min(max(side, 4), 16) ** 2
    side = round(math.sqrt(per_light))
    if per_light < 1 or side * side != per_light:
        raise ValueError(f"per_light must be a square number, got {per_light}")
    n_pixels = min(points, RAY_BUDGET // (n_lights * per_light)) // PER_PIXEL
    result = LightChoice(points=0, lights=n_lights, per_light=per_light, bsdf_samples=bsdf_samples)
    if n_pixels * PER_PIXEL < MIN_POINTS:
        result.skipped = (
            f"{n_lights} lights are too many for the brute-force oracle ({MIN_POINTS} points x {n_lights} lights x "
            f"{per_light} samples would exceed {RAY_BUDGET} shadow rays)"
        )
        return result
    arrays = scene.compile()
    tracer = RayTracer(arrays)
    env = (scene.environment if scene.environment is not None else _placeholder()).kernel
    rng = np.random.default_rng(seed)
    try:
        rng_pixels = np.random.default_rng(seed)
        chosen, weight = _stratified_pixels(scene, arrays, lights, env, tracer, n_pixels, rng_pixels)
        cams = _camera_samples(scene, arrays, lights, env, tracer, chosen, weight, rng_pixels)
        pts = cams.points
        result.points, result.textured = pts.point.shape[0], cams.textured
        if result.points == 0:
            result.skipped = "the camera sees no surface to shade"
            return result
        cache: dict = {}

        def terms_for(light_strategy: str, compensated: np.ndarray):
            key = (light_strategy, compensated.tobytes())
            if key not in cache:
                cache[key] = (
                    _light_terms(arrays, lights, env, tracer, pts, compensated, light_strategy, per_light, rng),
                    _bsdf_terms(arrays, lights, env, tracer, pts, compensated, light_strategy, bsdf_samples, rng),
                )
            return cache[key]

        _selectors(result, scene, strategies, user_selectors, lights, arrays, cams, terms_for, seed, keep_tables)
        for label, settings, table in strategies:
            _split(result, scene, label, settings, table, cams, arrays, terms_for)
    finally:
        tracer.close()
    result.seconds = time.perf_counter() - start
    return result


def check_selectors(scene: Scene, user_selectors, *, points: int = 64, seed: int = 11) -> None:
    """Run the guards' checks of ``user_selectors`` at ``points`` camera samples' shading points (cheap: no light is
    sampled), so that a selector that breaks its contract fails before anything is rendered; a scene with fewer than
    two lights is an error (there is no choice to make)."""
    if not user_selectors:
        return
    lights = scene.light_table()
    if lights.kind.shape[0] < 2:
        raise ParameterError(
            f"scene {scene.name!r} has {lights.kind.shape[0]} light(s): a light selector needs two or more to choose "
            "from"
        )
    arrays = scene.compile()
    tracer = RayTracer(arrays)
    env = (scene.environment if scene.environment is not None else _placeholder()).kernel
    try:
        with quiet_compiling():
            # random pixels: the checks need shading points, not the measurement's stratified sample of the image
            rng = np.random.default_rng(seed)
            width, height = scene.camera.resolution
            chosen = rng.choice(width * height, min(width * height, max(1, points // PER_PIXEL)), replace=False)
            pts = _camera_samples(scene, arrays, lights, env, tracer, chosen, np.ones(chosen.size), rng).points
    finally:
        tracer.close()
    if pts.point.shape[0] == 0:
        return
    for guarded in user_selectors:
        guarded.pmf_matrix(pts.point, pts.gnormal, lights, seed=seed)


def _selectors(result, scene, strategies, user_selectors, lights, arrays, cams, terms_for, seed, keep_tables) -> None:
    """The table of selectors, light sampling alone (no MIS weight), with the first strategy's light sampling."""
    pts = cams.points
    plan = resolve(scene, strategies[0][1] if strategies else RenderSettings())
    compensated = _compensated_materials(arrays.material_kind, plan.compensated)[pts.material]
    light_terms, _ = terms_for(plan.settings.light_strategy, compensated)
    moments = _light_moments(light_terms, None)
    m, u = moments[0], moments[1]
    result.arriving = float(m.sum() / max(u.sum(), 1e-300))
    pmfs = {name: _selector_pmf(_built(name, lights, scene), pts, compensated) for name in BUILTIN_SELECTORS}
    for label, settings, table in strategies:
        if settings.light_sampler == "learned":  # what its render learned; one that learned nothing picks as the BVH
            learned = resolve(scene, settings).selector
            if table is not None and cells_learned(table) > 0:
                pmfs[f"learned ({label})"] = _selector_pmf(restored(learned, table), pts, compensated)
            else:
                pmfs[f"learned ({label}): learned nothing, the bvh"] = _selector_pmf(learned, pts, compensated)
    for guarded in user_selectors:
        pmfs[guarded.label] = guarded.pmf_matrix(pts.point, pts.gnormal, lights, seed=seed)
    pmfs["unoccluded oracle"] = u / np.maximum(u.sum(axis=1, keepdims=True), 1e-300)
    pmfs["oracle"] = m / np.maximum(m.sum(axis=1, keepdims=True), 1e-300)
    rms = np.sqrt(moments[2])
    pmfs["variance-optimal"] = rms / np.maximum(rms.sum(axis=1, keepdims=True), 1e-300)
    oracle_mean, *oracle_parts = _light_variance(moments, pmfs["oracle"])
    weight = cams.point_weights()
    if keep_tables:
        result.tables = {"g": light_terms.g, "seen": light_terms.seen, "pmfs": pmfs, "weight": weight}
    oracle_total = _relative(sum(oracle_parts), oracle_mean, weight)
    for name, pmf in pmfs.items():
        mean, choice, point, visibility = _light_variance(moments, pmf)
        if name == "oracle":
            choice = np.zeros_like(choice)  # by construction: what is left is rounding
        total = _relative(choice + point + visibility, mean, weight)
        result.selectors.append(
            SelectorRow(name, _relative(choice, mean, weight), total, total / oracle_total if oracle_total > 0 else 1.0)
        )


def _split(result: LightChoice, scene, label, settings, table, cams: _CameraSamples, arrays, terms_for) -> None:
    """Strategy ``label``'s variance of one camera sample, split, each term a share of the pixels' 1-spp relMSE."""
    if settings.strategy not in SPLIT_STRATEGIES:
        result.unsplit[label] = f"strategy {settings.strategy!r} samples neither the lights nor the BSDF"
        return
    pts = cams.points
    plan = resolve(scene, settings)
    resolved = plan.settings
    selector = plan.selector
    if resolved.light_sampler == "learned" and table is not None:
        selector = restored(selector, table)
    compensated = _compensated_materials(arrays.material_kind, compensation_for(scene, resolved))[pts.material]
    light_terms, bsdf_terms = terms_for(resolved.light_strategy, compensated)
    pmf = _selector_pmf(selector, pts, compensated)
    slots = resolved.n_bsdf + resolved.light_samples
    n_points = pts.point.shape[0]
    weight = None
    if resolved.strategy == "mis":
        n_light, n_bsdf = resolved.light_samples, resolved.n_bsdf
        beta = 1.0 if resolved.heuristic == "balance" else 2.0
        weight = _light_weights(light_terms, pmf, n_light, n_bsdf, beta) if n_bsdf else None
        bsdf = _bsdf_values(bsdf_terms, n_points, pmf, n_light, n_bsdf, beta)
    elif resolved.strategy == "env":
        n_light, n_bsdf, bsdf = slots, 0, np.zeros((n_points, 1))
    else:
        n_light, n_bsdf = 0, slots
        bsdf = _bsdf_values(bsdf_terms, n_points, None, 0, slots, 1.0)
    zero = np.zeros(n_points)
    mean_l, choice, point, visibility, noise_l = zero, zero, zero, zero, zero
    if n_light:
        moments = _light_moments(light_terms, weight)
        mean_l, choice, point, visibility = _light_variance(moments, pmf)
        m, _, s2, _ = moments
        noise_l = np.where(pmf > 0.0, s2 - m * m, 0.0).sum(axis=1) / light_terms.g.shape[2]
    var_bsdf = bsdf.var(axis=1) if n_bsdf else zero
    terms = {
        "choice": choice / max(n_light, 1),
        "point": point / max(n_light, 1),
        "visibility": visibility / max(n_light, 1),
        "bsdf": var_bsdf / max(n_bsdf, 1),
    }
    # per camera sample: what it sees itself plus the direct light at its point (estimated: noise is that estimate's
    # variance, taken out of the spread within the pixel), and its terms (0 where there is nothing to shade)
    row = cams.shaded
    shaded = row >= 0
    value = cams.seen.copy()
    value[shaded] += (mean_l + bsdf.mean(axis=1))[row[shaded]]
    noise = np.zeros(row.size)
    noise[shaded] = (noise_l + var_bsdf / bsdf.shape[1])[row[shaded]]
    per_pixel = value.reshape(-1, PER_PIXEL)
    guard = per_pixel.mean(axis=1) ** 2 + RELMSE_EPSILON
    shares = {}
    for name, term in terms.items():
        t = np.zeros(row.size)
        t[shaded] = term[row[shaded]]
        shares[name] = float(np.sum(cams.weight * t.reshape(-1, PER_PIXEL).mean(axis=1) / guard))
    spread = per_pixel.var(axis=1, ddof=1) - noise.reshape(-1, PER_PIXEL).mean(axis=1)
    result.splits.append(
        Split(
            label,
            resolved.light_sampler if n_light else "-",
            **shares,
            pixel=float(np.sum(cams.weight * spread / guard)),
        )
    )


def _built(name: str, lights, scene):
    environment = scene.environment
    return build_selector(
        name,
        lights,
        env_irradiance=environment.irradiance_terms if environment is not None else None,
        env_irradiance_compensated=environment.compensated_irradiance_terms if environment is not None else None,
    )


def _placeholder():
    from ..emitters.envmap import placeholder_environment

    return placeholder_environment()


# --- lightprobe check for a selector ----------------------------------------------------------------------------------
#: what ``check_selector`` verifies, in order (each a check the guard makes)
SELECTOR_CHECKS = (
    "select and pmf run, with (N,) results of the right dtype",
    "pmfs sum to 1 over the lights at every point",
    "select's light indices in range, each with pmf > 0",
    "select's pmf = pmf()",
    f"picks follow pmf() (chi-square, {PICKS} picks at {PICK_POINTS} points)",
)


def selector_test_scene():
    """The scene ``lightprobe check`` tries a selector on: a floor and a wall seen from above, lit by rectangles of
    three sizes and powers, an emissive sphere, a point light, a spot light and a grey sky (every kind of row a
    selector meets, bounded and infinite)."""
    from ..bsdfs import Lambert, Phong
    from ..emitters.envmap import EnvironmentMap
    from ..emitters.procedural import constant
    from ..emitters.punctual import PointLight, SpotLight
    from ..geometry.camera import Camera
    from ..geometry.shapes import Rectangle, Sphere
    from ..scene import Scene

    scene = Scene(Camera([0, 3, 4], [0, 0, 0], fov=50, resolution=(32, 24)), EnvironmentMap.from_array(constant(0.2)))
    scene.add(Rectangle.ground(size=12), Lambert(0.5), name="floor")
    scene.add(Rectangle([-3, 0, -2], [0, 2, 0], [0, 0, 4]), Phong(0.3, 0.4, 30), name="wall")
    for i, (x, size, emission) in enumerate(((-1.5, 0.3, 40.0), (0.0, 0.8, 5.0), (1.5, 1.5, 1.0))):
        scene.add(Rectangle([x, 2.5, -0.5], [size, 0, 0], [0, 0, size]), None, emission=emission, name=f"panel{i}")
    scene.add(Sphere([1.0, 0.4, 1.0], 0.2), None, emission=8.0, name="bulb")
    scene.add_light(PointLight([-1.0, 1.0, 1.5], 3.0))
    scene.add_light(SpotLight([2.0, 2.0, 0.0], [2.0, 0.0, 0.0], 20.0, cone_angle=25.0))
    return scene


def check_selector(selector, *, points: int = 64, seed: int = 0) -> list[str]:
    """Every check of :data:`SELECTOR_CHECKS` on :func:`selector_test_scene` at ``points`` shading points; the
    checks passed, or a :class:`TechniqueError` naming the first that failed."""
    check_selectors(selector_test_scene(), [selector], points=points, seed=seed)
    return list(SELECTOR_CHECKS)
