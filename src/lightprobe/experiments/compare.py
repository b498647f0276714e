"""Which strategy wins on a scene: each rendered at equal samples or equal time, measured against a reference.

A strategy is a name with optional setting overrides: ``env``, ``brdf``, ``mis`` (the renderer's defaults, counts
uniform as below), ``mis-power``, ``mis-balance``, ``mis-compensated`` (the compensated environment PDF on every
material; the defaults take it on Lambertian ones), ``uniform``, ``cosine``, then ``/key=value`` with any
``[render]`` key of a scene file,
e.g. ``mis-power/sampler=independent`` or ``env/light_sampler=bvh/lights_per_sample=4``.

Each strategy renders in doubling rounds (1, 2, 4, ... samples per pixel; 8, 16, ... under a learned light selection,
which learns from its first 4 in a first round without a time limit), each round continuing the previous one
(``render(..., resume=...)``), so the convergence curve costs no more than the final image.  In ``time`` mode the
last round stops at the time budget (at the end of a short pass), so every strategy gets the same seconds of
rendering; in ``spp`` mode every strategy gets the same samples.  Metrics (``lightprobe.analysis.metrics``) are
taken against the reference after every round.

A strategy may also be a user's sampling technique (``lightprobe.lab``): ``FILE.py[:NAME]`` alone,
``mis:FILE.py[:NAME]`` under MIS with lightprobe's technique of the other kind, ``mis:A.py:X+B.py:Y`` two of the
user's; it renders with the laboratory's estimator (``lab/render.py``), in rounds like any other, and may take
``/key=value`` overrides (seed, sampler, bsdf_samples, env_samples, heuristic).

A strategy's counts are uniform, whatever the renderer's automatic choice: its rounds continue each other (decisions.md
99).  An adaptive strategy (``/adaptive=true``, integrators/adaptive.py) cannot continue a render: its counts need the
whole pilot.  Its rounds are separate renders, each timed on its own, so its curve costs about twice its final
image: 4, 8, ... spp, then spp on average in ``spp`` mode; an eighth, a quarter, half and all of the budget in
``time`` mode, where each render plans its pilot and mean count to fit its time limit.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..analysis import metrics
from ..errors import LightprobeError
from ..integrators.light_learning import UNIFORM_PILOT
from ..integrators.wavefront import RenderSettings, learns_light_selection, render, result_from, settings_for
from ..scene import Scene

__all__ = ["PRESETS", "StrategyRun", "compare", "light_choice", "parse_strategy"]

# An adaptive strategy's mean count at equal time is what its time limit buys; this only keeps it finite.
_TIME_MODE_SPP = 1 << 20

PRESETS = {
    "uniform": {"strategy": "uniform"},
    "cosine": {"strategy": "cosine"},
    "brdf": {"strategy": "brdf"},
    "env": {"strategy": "env"},
    "mis": {"strategy": "mis"},  # the renderer's defaults
    "mis-power": {"strategy": "mis", "heuristic": "power"},
    "mis-balance": {"strategy": "mis", "heuristic": "balance"},
    "mis-compensated": {"strategy": "mis", "mis_compensation": True},
}


def _value(text: str):
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def parse_strategy(
    token: str, base: RenderSettings, equal: str = "spp", spp: int | None = None
) -> tuple[str, RenderSettings]:
    """(label, settings) for a strategy token, to be compared at ``equal`` samples (``spp`` of them, if given) or
    time; a :class:`LightprobeError` names a bad token."""
    label, settings, _ = parse_any_strategy(token, base, equal, spp)
    return label, settings


#: the render keys a user technique's strategy may override
LAB_KEYS = ("seed", "sampler", "bsdf_samples", "env_samples", "heuristic")


def parse_any_strategy(token: str, base: RenderSettings, equal: str = "spp", spp: int | None = None):
    """(label, settings, lab strategy or None) for a strategy token: see :func:`parse_strategy`."""
    from ..integrators.settings import options, settings_from_table
    from ..lab.render import is_lab_token, parse_lab_token

    keys = {o.key for o in options().values() if o.key is not None} - {"spp"}
    lab = None
    if is_lab_token(token):
        lab, overrides = parse_lab_token(token)
        keys = set(LAB_KEYS)
        changes = {}
    else:
        name, *overrides = [part.strip() for part in token.strip().split("/")]
        if name not in PRESETS:
            raise LightprobeError(f"unknown strategy {name!r} in {token!r}; use {', '.join(PRESETS)} or FILE.py:NAME")
        changes = dict(PRESETS[name])
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep or key.strip() not in keys:
            allowed = ", ".join(sorted(keys))
            raise LightprobeError(f"strategy {token!r}: {item!r} is not key=value with a key among {allowed}")
        changes.update(settings_from_table({key.strip(): _value(value)}))
    settings = dataclasses.replace(base, **changes)
    if settings.adaptive is True and equal == "spp" and spp is not None and spp < 4:
        raise LightprobeError(f"strategy {token!r}: adaptive sampling needs spp >= 4 (a pilot first), got {spp}")
    try:  # an adaptive strategy's spp is each round's (>= 4, checked against compare's spp when it runs)
        (dataclasses.replace(settings, spp=max(settings.spp, 4)) if settings.adaptive else settings).validate()
    except LightprobeError as exc:
        raise LightprobeError(f"strategy {token!r}: {exc}") from None
    return token.strip(), settings, lab


@dataclass
class StrategyRun:
    """One strategy's final image and its convergence: a row per round."""

    label: str
    settings: RenderSettings
    image: np.ndarray = field(repr=False)
    variance: np.ndarray = field(repr=False)
    seconds: float = 0.0
    spp: float = 0.0
    rounds: list[dict] = field(default_factory=list)
    metrics: dict = field(default_factory=dict)
    #: why the strategy stopped early (a user technique that failed mid-render), or None; its rounds so far count
    error: str | None = None
    #: what its light selection learned (``light_sampler = "learned"``: integrators/light_learning.py), or None
    learned: dict | None = None
    #: each pixel's camera samples (the variance is of their mean)
    counts: np.ndarray | None = field(default=None, repr=False)


def _measure(image, variance, reference, reference_variance, mask=None) -> dict:
    b = metrics.bias(image, reference, variance, reference_variance, mask=mask)
    return {
        "mse": metrics.mse(image, reference, mask),
        "relmse": metrics.relmse(image, reference, mask),
        "psnr": metrics.psnr(image, reference, mask),
        "mean_variance": metrics.mean_variance(variance, mask),
        "bias": b.estimate,
        "bias_low": b.low,
        "bias_high": b.high,
    }


def run_strategy(
    scene: Scene,
    label: str,
    settings: RenderSettings,
    reference: np.ndarray,
    reference_variance: np.ndarray | None,
    *,
    equal: str,
    spp: int,
    seconds: float,
    progress: Callable[[str, float], None] | None = None,
    masks: dict[str, np.ndarray] | None = None,
    lab=None,
) -> StrategyRun:
    """Render one strategy in doubling rounds up to ``spp`` samples (``equal='spp'``) or ``seconds`` of rendering
    (``equal='time'``), measuring after each round; ``masks`` (name -> (H, W) bool) add per-object metrics;
    ``lab``: a user technique's strategy (:class:`lightprobe.lab.render.LabStrategy`), rendered by the laboratory."""
    if lab is not None:
        from ..lab.render import render_lab

        def renderer(scene, part, resume):
            return render_lab(scene, lab, part, resume=resume)

    else:

        def renderer(scene, part, resume):
            return render(scene, part, resume=resume)

    width, height = scene.camera.resolution
    acc = None
    done = 0
    spent = 0.0
    # a learned light selection learns in a render of more than its first UNIFORM_PILOT samples without a time limit
    # (integrators/wavefront.py), and the rounds after it continue with what it learned: its first round takes twice
    # the pilot, whole (in time mode it may overrun the budget: its seconds say so); a shorter one would learn nothing.
    # Only where there is something to learn (two bounded lights or more, light samples taken): the default selector
    # is the learned one, and an environment map's strategies keep their rounds of 1, 2, 4, ... samples
    learning = lab is None and settings.light_sampler == "learned" and learns_light_selection(scene, settings)
    target = 2 * UNIFORM_PILOT if learning else 1
    # the report states the allocation and heuristic actually used; a strategy's rounds continue each other, so its
    # counts are uniform unless it asks for adaptive ones (adaptive=true: separate renders, _adaptive_rounds)
    settings = settings_for(scene, settings.uniform_unless_adaptive())
    run = StrategyRun(label, settings, np.zeros((height, width, 3), np.float32), np.zeros((height, width, 3)))
    # short passes in time mode, so that the budget is met within a pass of a few milliseconds: a pass holds about
    # 2^17 shading samples (RIS candidates counted), whatever the strategy's samples per camera sample
    work = settings.n_bsdf + settings.light_samples * settings.env_candidates
    pass_samples = max(width * height, (1 << 17) // work) if equal == "time" else settings.pass_samples
    if settings.adaptive:
        timed = dataclasses.replace(settings, pass_samples=pass_samples)
        _adaptive_rounds(scene, run, timed, reference, spp if equal == "spp" else None, seconds, progress)
        return _final_metrics(run, reference, reference_variance, masks)
    while True:
        if equal == "spp":
            if done >= spp:
                break
            n = min(target, spp) - done
            limit = None
        else:
            limit = seconds - spent
            if limit <= 0.0:
                break
            n = max(target - done, 1)
        if learning and done == 0:
            limit = None
        part = dataclasses.replace(settings, spp=n, first_sample=done, time_limit=limit, pass_samples=pass_samples)
        try:
            result = renderer(scene, part, acc)
        except LightprobeError as exc:
            partial = getattr(exc, "result", None)
            if acc is None and partial is None:
                raise
            run.error = str(exc)  # keep the rounds so far (and the failing round's samples, if any)
            if partial is not None:
                acc = partial.accumulator
                spent += partial.stats["seconds"]
                final = result_from(acc, width, height)
                run.image, run.variance = final.image, final.variance
            break
        if acc is None and not result.accumulator.count.any():  # a user technique's call outlasted the budget
            raise LightprobeError(f"strategy {label!r}: the {seconds:g} s ran out before its first pass was finished")
        acc = result.accumulator
        spent += result.stats["seconds"]
        done = int(acc.count.min())
        final = result_from(acc, width, height)
        run.rounds.append(
            {"spp": float(acc.count.mean()), "seconds": spent, **_measure(final.image, final.variance, reference, None)}
        )
        run.image, run.variance = final.image, final.variance
        if progress is not None:
            progress(label, spent / seconds if equal == "time" else done / spp)
        if result.stats["stopped_by_time_limit"] or result.stats["interrupted"]:
            break  # counts are uneven now: a further round could not continue them in order
        target *= 2
    if acc is None:
        raise LightprobeError(f"strategy {label!r} rendered nothing")
    run.learned, run.counts = acc.learned, acc.count.reshape(height, width).copy()
    run.seconds = spent
    run.spp = float(acc.count.mean())
    return _final_metrics(run, reference, reference_variance, masks)


def _adaptive_rounds(
    scene, run: StrategyRun, settings: RenderSettings, reference, spp: int | None, seconds: float, progress
) -> None:
    """An adaptive strategy's rounds, separate renders, the last one the strategy's image and seconds: 4, 8, ...
    and finally ``spp`` samples per pixel on average, or (``spp`` None) an eighth, a quarter, half and all of
    ``seconds`` as time limits, each render planning its own pilot and mean count (integrators/adaptive.py)."""
    if spp is not None:
        targets = [n for n in (4 << k for k in range(spp.bit_length())) if n < spp] + [spp]
        budgets = [None] * len(targets)
    else:
        budgets = [seconds / 8, seconds / 4, seconds / 2, seconds]
        targets = [_TIME_MODE_SPP] * len(budgets)
    for i, (n, budget) in enumerate(zip(targets, budgets, strict=True)):
        result = render(scene, dataclasses.replace(settings, spp=n, first_sample=0, time_limit=budget))
        run.image, run.variance = result.image, result.variance
        run.learned, run.counts = result.accumulator.learned, result.counts
        run.seconds, run.spp = result.stats["seconds"], float(result.counts.mean())
        run.rounds.append(
            {"spp": run.spp, "seconds": run.seconds, **_measure(result.image, result.variance, reference, None)}
        )
        if progress is not None:
            progress(run.label, (i + 1) / len(targets))
        if result.stats["interrupted"]:
            break


def _final_metrics(run: StrategyRun, reference, reference_variance, masks) -> StrategyRun:
    """The final image's metrics: against the reference, per object, FLIP and efficiency."""
    spent = run.seconds
    run.metrics = _measure(run.image, run.variance, reference, reference_variance)
    run.metrics["flip"] = metrics.flip(run.image, reference)
    run.metrics["efficiency"] = metrics.efficiency(max(run.metrics["mse"], 1e-300), max(spent, 1e-9))
    run.metrics["objects"] = {
        name: _measure(run.image, run.variance, reference, reference_variance, mask)
        for name, mask in (masks or {}).items()
        if mask.any()
    }
    return run


def compare(
    scene: Scene,
    strategies: list[str],
    reference: np.ndarray,
    reference_variance: np.ndarray | None = None,
    *,
    base: RenderSettings | None = None,
    equal: str = "spp",
    spp: int = 64,
    seconds: float = 10.0,
    progress: Callable[[str, float], None] | None = None,
    masks: dict[str, np.ndarray] | None = None,
) -> list[StrategyRun]:
    """Render every strategy and measure it; each run's ``metrics['relative_efficiency']`` is its efficiency over
    the best one's, and ``metrics['objects'][name]`` its metrics on each of ``masks`` (e.g. from
    :func:`lightprobe.analysis.masks.object_id_pass`)."""
    if equal not in ("spp", "time"):
        raise LightprobeError(f"equal must be 'spp' or 'time', got {equal!r}")
    if equal == "spp" and spp < 1:
        raise LightprobeError(f"spp must be >= 1, got {spp}")
    if equal == "time" and not seconds > 0:
        raise LightprobeError(f"seconds must be > 0, got {seconds}")
    if not strategies:
        raise LightprobeError("give at least one strategy")
    width, height = scene.camera.resolution
    if reference.shape[:2] != (height, width):
        raise LightprobeError(f"the reference is {reference.shape[1]}x{reference.shape[0]}, the scene {width}x{height}")
    base = base or RenderSettings()
    parsed = [parse_any_strategy(token, base, equal, spp) for token in strategies]
    runs = []
    for label, settings, lab in parsed:
        start = time.perf_counter()
        runs.append(
            run_strategy(
                scene,
                label,
                settings,
                reference,
                reference_variance,
                equal=equal,
                spp=spp,
                seconds=seconds,
                progress=progress,
                masks=masks,
                lab=lab,
            )
        )
        runs[-1].metrics["wall_seconds"] = time.perf_counter() - start
    best = max(r.metrics["efficiency"] for r in runs)
    for r in runs:
        r.metrics["relative_efficiency"] = r.metrics["efficiency"] / best
    return runs


def per_sample_relmse(run: StrategyRun, reference: np.ndarray) -> float:
    """The variance of one camera sample as a relMSE, from the run's own samples: the mean over the pixels of
    lum(variance of the mean) x count / (lum(reference)^2 + ``metrics.RELMSE_EPSILON``) (the spread of the samples,
    not the error of the image: a Sobol' render's image does better)."""
    from ..color import luminance

    ref = luminance(np.asarray(reference[..., :3], dtype=np.float64))
    spread = luminance(np.asarray(run.variance, dtype=np.float64)) * run.counts
    return float(np.mean(spread / (ref * ref + metrics.RELMSE_EPSILON)))


def light_choice(scene: Scene, runs: list[StrategyRun], reference: np.ndarray, *, user_selectors=(), points: int = 512):
    """How far each light selector is from the oracle and where each run's variance comes from
    (:func:`lightprobe.experiments.light_choice.measure`), each split beside the run's own per-sample relMSE
    (``measured``); None for a scene with fewer than two lights."""
    from .light_choice import measure

    found = measure(
        scene, [(r.label, r.settings, r.learned) for r in runs], points=points, user_selectors=user_selectors
    )
    if found is not None:
        found.measured = {r.label: per_sample_relmse(r, reference) for r in runs if r.counts is not None}
    return found
