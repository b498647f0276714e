"""How to render: :class:`RenderSettings`, each option declared once.

Every field of :class:`RenderSettings` carries its declaration (:class:`Option`, in the field's metadata): its help
text, its type and range, the ``[render]`` key of scene files that sets it and the command-line flags that do.
From that one declaration come :meth:`RenderSettings.validate` (type and range, with a message naming the option),
the scene file's ``[render]`` table (:func:`read_render_table`), ``lightprobe render``'s options
(``cli.render_options``) and the render's sidecar (:func:`settings_record`); a new option is one field here.  What
one field cannot say (sample counts that must add up, a pilot that needs ``spp >= 4``) is checked at the end of
:meth:`RenderSettings.validate`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

from ..emitters.area import STRATEGIES as LIGHT_STRATEGIES
from ..emitters.selection import SELECTORS
from ..errors import ParameterError
from ..sampling.rng import SAMPLERS
from . import adaptive
from .techniques import STRATEGIES

__all__ = [
    "DIFFUSE",
    "HEURISTICS",
    "RESOLVED_PER_SCENE",
    "Option",
    "RenderSettings",
    "options",
    "read_render_table",
    "settings_from_table",
    "settings_record",
]

HEURISTICS = {"balance": 1.0, "power": 2.0}
DIFFUSE = "diffuse"  # mis_compensation's automatic choice: the compensated PDF on Lambertian materials only

# n_bsdf=None and n_env=None in scenes lit by an environment map alone (decisions.md 33, 34, 93); else 1 each
AUTO_BSDF_SAMPLES = 8
AUTO_ENV_SAMPLES = 8
# from this many bounded lights (light BVH rows: emissive triangles, spheres, rectangles, point and spot lights) a
# camera sample picks MANY_LIGHTS_PICKS lights, not 2: where the choice of light is most of the error, the picks of one
# camera sample share one stratified set of pick numbers (decisions.md 118)
MANY_LIGHTS = 64
MANY_LIGHTS_PICKS = 4
# the shading samples (slots: n_bsdf + lights_per_sample x n_env) one camera sample holds; with LAST_SAMPLE, a sample
# index times the slots stays below 2^63 (sampling.rng.group_slot numbers a group's members k n + j)
MAX_SLOTS = 64
# the fields whose None RenderSettings.resolved turns into a value chosen for the scene
RESOLVED_PER_SCENE = ("n_bsdf", "n_env", "heuristic", "lights_per_sample", "adaptive")
# adaptive=None: adaptive counts at spp >= 16, a pilot of 4 spp or more (at 8 spp, a 2-spp pilot, they cut the
# error 1.4-1.8x for 1.3-2.4x the time on the demo scenes: no clear win; at 4-7 spp a 1-spp pilot shows no noise;
# decisions.md 99)
AUTO_ADAPTIVE_MIN_SPP = 16
LAST_SAMPLE = 2**56  # a sample index times 64 shading slots stays below 2^63 (sampling.rng.group_slot)

_KINDS = {"integer": numbers.Integral, "number": numbers.Real, "string": str, "true or false": bool}


@dataclass(frozen=True)
class Option:
    """One render option: ``kind`` is "integer", "number", "string" or "true or false"; a string takes one of
    ``choices``; numbers lie in [``minimum``, ``maximum``] (``above``: strictly above ``minimum``).  ``key``: its
    ``[render]`` key in scene files (None: not settable there); ``flags``: its command-line flags (None: no option;
    a "--x/--no-x" pair for a boolean); ``auto``: what None means, for the help."""

    help: str
    kind: str
    choices: Callable[[], dict] | None = None
    minimum: float | None = None
    maximum: float | None = None
    above: bool = False
    key: str | None = None
    flags: tuple[str, ...] | None = None
    auto: str | None = None

    def check(self, name: str, value) -> None:
        """Raise :class:`ParameterError` naming ``name`` if ``value`` is of the wrong type or out of range."""
        if value is None and self.auto is not None:
            return
        ok = isinstance(value, _KINDS[self.kind]) and not (self.kind != "true or false" and isinstance(value, bool))
        if not ok:
            article = "" if self.kind == "true or false" else "an " if self.kind == "integer" else "a "
            raise ParameterError(f"{name} must be {article}{self.kind}, got {value!r}")
        if self.choices is not None and value not in self.choices():
            raise ParameterError(f"{name} must be one of {list(self.choices())}, got {value!r}")
        if self.kind in ("integer", "number"):
            low = self.minimum is not None and (value <= self.minimum if self.above else value < self.minimum)
            high = self.maximum is not None and value > self.maximum
            if low or high or (self.kind == "number" and not math.isfinite(value)):
                raise ParameterError(f"{name} must be {self.range_text()}, got {value!r}")

    def range_text(self) -> str:
        if self.minimum is not None and self.maximum is not None:
            return f"from {_number(self.minimum)} to {_number(self.maximum)}"
        if self.minimum is not None:
            return f"{'>' if self.above else '>='} {_number(self.minimum)}"
        return f"a {self.kind}"


def _number(x) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def option(default, help: str, kind: str, **declaration):
    """A dataclass field with its :class:`Option` declaration."""
    return field(default=default, metadata={"option": Option(help, kind, **declaration)})


@dataclass(frozen=True)
class RenderSettings:
    """How to render; each field's declaration (metadata ``"option"``) says what it means and how it is given."""

    spp: int = option(16, "Camera samples per pixel", "integer", minimum=1, key="spp", flags=("--spp",))
    strategy: str = option(
        "mis",
        "uniform, cosine, brdf, env (light sampling) or mis",
        "string",
        choices=lambda: STRATEGIES,
        key="strategy",
        flags=("--strategy",),
    )
    heuristic: str | None = option(
        None,
        "MIS heuristic: balance or power",
        "string",
        choices=lambda: HEURISTICS,
        key="heuristic",
        flags=("--heuristic",),
        auto="balance if only an environment map lights the scene, else power",
    )
    n_bsdf: int | None = option(
        None,
        "BSDF samples per camera sample",
        "integer",
        minimum=0,
        key="bsdf_samples",
        flags=("--bsdf-samples",),
        auto="8 if only an environment map lights the scene, 2 if one lights it beside other lights, else 1",
    )
    n_env: int | None = option(
        None,
        "Samples per picked light, N",
        "integer",
        minimum=0,
        key="env_samples",
        flags=("--env-samples", "--light-samples"),
        auto="8 if only an environment map lights the scene, else 1",
    )
    seed: int = option(0, "Random seed", "integer", minimum=0, maximum=2**63 - 1, key="seed", flags=("--seed",))
    first_sample: int = option(0, "Index of the first sample (split and resumed renders)", "integer", minimum=0)
    sampler: str = option(
        "sobol",
        "Random numbers: sobol (Owen-scrambled Sobol') or independent",
        "string",
        choices=lambda: SAMPLERS,
        key="sampler",
        flags=("--sampler",),
    )
    env_candidates: int = option(
        1,
        "Resample each environment sample from this many candidates (RIS; env maps alone)",
        "integer",
        minimum=1,
        maximum=64,
        key="env_candidates",
        flags=("--env-candidates",),
    )
    mis_compensation: bool | None = option(
        None,
        "Sample the MIS-compensated env PDF on every material / on none",
        "true or false",
        key="mis_compensation",
        flags=("--mis-compensation/--no-mis-compensation",),
        auto="mis with an environment map and BSDF samples: on diffuse materials",
    )
    light_sampler: str = option(
        "learned",
        "How a light is picked: uniform, power, bvh, or learned (the default: the BVH, and what the pilot learns "
        "of which lights reach the shading points, shadows included)",
        "string",
        choices=lambda: SELECTORS,
        key="light_sampler",
        flags=("--light-sampler",),
    )
    lights_per_sample: int | None = option(
        None,
        "Lights picked per camera sample, K (each gets --env-samples samples)",
        "integer",
        minimum=1,  # at most 64 slots in all: validate()
        key="lights_per_sample",
        flags=("--lights-per-sample",),
        auto="1 if an environment map or one delta light is the only light, 4 with 64 bounded lights or more (in a "
        "render long enough, 4, 8 or 16 as a probe of the image finds best), else 2",
    )
    light_strategy: str = option(
        "solid-angle",
        "How an area light is sampled: area, solid-angle, hemisphere, cosine",
        "string",
        choices=lambda: LIGHT_STRATEGIES,
        key="light_strategy",
        flags=("--light-strategy",),
    )
    time_limit: float | None = option(
        None,
        "Stop after this many seconds (keeps the result)",
        "number",
        minimum=0,
        above=True,
        flags=("--time-limit",),
        auto="no limit",
    )
    threads: int | None = option(
        None, "Threads", "integer", minimum=1, maximum=256, flags=("--threads",), auto="all cores"
    )
    pass_samples: int | None = option(
        None, "Camera samples per pass", "integer", minimum=1, auto="wavefront.PASS_CAMERA_SAMPLES"
    )
    adaptive: bool | None = option(
        None,
        "A pilot of about spp / 4 samples in every pixel, then --spp on average where the noise is (with "
        "--time-limit: as much of both as the limit affords); off: spp samples in every pixel",
        "true or false",
        key="adaptive",
        flags=("--adaptive/--no-adaptive",),
        auto=f"on at spp >= {AUTO_ADAPTIVE_MIN_SPP}; off below, and for references, sample ranges and resumed renders",
    )
    outline_control_variate: bool = option(
        True,
        "Where an emitter seen directly has its outline in a pixel, take the emitter's exact share of the pixel "
        "and let the camera samples estimate only the rest (a control variate: the mean is unchanged)",
        "true or false",
        key="outline_control_variate",
        flags=("--outline-control-variate/--no-outline-control-variate",),
    )

    def validate(self) -> None:
        """Raise :class:`ParameterError` naming the first setting of the wrong type or out of range, then the
        first combination that cannot be rendered."""
        for f in fields(self):
            f.metadata["option"].check(f.name, getattr(self, f.name))
        # automatic counts: at least 1 each (render checks the counts it resolves them to again)
        n_bsdf = 1 if self.n_bsdf is None else self.n_bsdf
        n_env = 1 if self.n_env is None else self.n_env
        if n_bsdf + n_env < 1 or n_bsdf + n_env > MAX_SLOTS:
            raise ParameterError(
                f"bsdf and env sample counts (n_bsdf, n_env) must be >= 0 with 1 to {MAX_SLOTS} in all, got {n_bsdf} "
                f"and {n_env}"
            )
        if self.shading_samples > MAX_SLOTS:
            raise ParameterError(
                f"lights_per_sample must be >= 1 with at most {MAX_SLOTS} shading samples in all "
                f"(n_bsdf + lights_per_sample x n_env), got {self.lights_per_sample}"
            )
        if self.mis_compensation and self.strategy != "mis":
            raise ParameterError("mis_compensation needs strategy 'mis' (the compensated PDF is zero on dim texels)")
        # a group's member j of sample k takes index k n + j (n <= 64 slots, sampling.rng.group_slot), in int64
        adaptive_counts = self.adaptive_counts()
        last = self.first_sample + self.spp * (adaptive.MAX_FACTOR if adaptive_counts else 1)
        if last > LAST_SAMPLE:
            what = "8 x spp (adaptive)" if adaptive_counts else "first_sample + spp"
            raise ParameterError(f"{what} must be at most 2^56 (sample indices x 64 slots in 64 bits), got {last}")
        if self.adaptive:
            if (problem := adaptive.check_spp(self.spp)) is not None:
                raise ParameterError(problem)
            if self.first_sample != 0:
                raise ParameterError("adaptive sampling renders samples from 0 (first_sample must be 0)")

    def adaptive_counts(self, resumed: bool = False) -> bool:
        """Whether the render takes adaptive per-pixel counts: ``adaptive`` if given, else (automatic) at spp >= 16
        from sample 0, unless it continues an earlier render (``resumed``).  A sample range or a continued render
        is uniform: adaptive counts need the whole pilot, so they cannot be split or resumed (decisions.md 36, 99)."""
        if self.adaptive is not None:
            return self.adaptive
        return self.spp >= AUTO_ADAPTIVE_MIN_SPP and self.first_sample == 0 and not resumed

    def uniform_unless_adaptive(self) -> RenderSettings:
        """These settings for a render made of sample ranges (a reference, a distributed render, compare's rounds):
        the automatic choice of adaptive counts made (uniform); an explicit ``adaptive=True`` is kept, for the
        caller to refuse."""
        return self if self.adaptive is not None else replace(self, adaptive=False)

    @property
    def light_samples(self) -> int:
        """Light slots per camera sample: K lights, ``n_env`` samples each (the lecture's K N; an automatic K or
        ``n_env`` counted as its smallest, 1, until :meth:`resolved` makes it concrete)."""
        return (self.lights_per_sample or 1) * (1 if self.n_env is None else self.n_env)

    @property
    def shading_samples(self) -> int:
        """Shading slots per camera sample (``n_bsdf``'s automatic value counted as its smallest, 1, until
        :meth:`resolved` makes it concrete)."""
        return (1 if self.n_bsdf is None else self.n_bsdf) + self.light_samples

    def resolved(
        self,
        environment_only: bool,
        one_delta_light: bool = False,
        environment: bool = False,
        resumed: bool = False,
        bounded_lights: int = 0,
    ) -> RenderSettings:
        """These settings with the automatic choices made, for a scene lit by an environment map alone or not
        (``one_delta_light``: by one point, spot or delta directional light alone; ``environment``: the scene has an
        environment map, alone or beside other lights).
        Measured on the peer scene and on eight of the seeds' sphere scenes (decisions.md 33, 34, 93): where the
        environment is the only light, 8 BSDF + 8 environment samples per camera sample with the balance heuristic give
        the lowest error per second of the allocations measured on the peer scene at 16, 64 and 256 spp, and beat 4 + 4
        in seven of the eight sphere scenes (a camera sample's samples of one technique are one stratified Sobol' set,
        whose error falls faster than 1/n; they cost no extra camera ray); with 4000 area lights and no map a second
        BSDF sample loses, so one there, and the power heuristic. The single-technique strategies take the same counts,
        so that every strategy traces n_bsdf + n_env directions per camera sample and equal samples mean equal rays.
        Where anything but an environment map alone lights the scene, K = 2 lights are picked per camera sample: the
        light samples' variance is most of such a scene's error (each pick's own Sobol' pair halves it), so a second
        pick lowers the error 1.7-1.9x for 1.4-1.5x the time (decisions.md 97); one delta light alone keeps K = 1 (its
        sample is always the same direction); a scene of 64 bounded lights or more takes K = 4, where the choice of
        light is most of the error and the picks' stratified numbers lower it faster than 1 / K (decisions.md 118); a
        render long enough then has its driver choose 4, 8 or 16 by a probe (integrators/picks.py, decisions.md 123).
        An environment map beside other lights takes 2 BSDF samples, which are how
        MIS finds the map's broad light (1.2-1.3x the efficiency of 1 on three such scenes; without a map a second one
        loses 9-18 %).  Adaptive counts as :meth:`adaptive_counts` decides (``resumed``: the render continues
        another)."""
        n_bsdf = self.n_bsdf
        if n_bsdf is None:
            n_bsdf = AUTO_BSDF_SAMPLES if environment_only else 2 if environment else 1
        n_env = self.n_env if self.n_env is not None else (AUTO_ENV_SAMPLES if environment_only else 1)
        k = self.lights_per_sample
        if k is None:
            # many lights take more picks where the 64 slots of a camera sample hold them
            many = bounded_lights >= MANY_LIGHTS and n_bsdf + MANY_LIGHTS_PICKS * n_env <= MAX_SLOTS
            k = 1 if environment_only or one_delta_light else MANY_LIGHTS_PICKS if many else 2
        heuristic = self.heuristic if self.heuristic is not None else ("balance" if environment_only else "power")
        return replace(
            self,
            n_bsdf=n_bsdf,
            n_env=n_env,
            heuristic=heuristic,
            lights_per_sample=k,
            adaptive=self.adaptive_counts(resumed),
        )


def options() -> dict[str, Option]:
    """Every field's declaration, by field name, in field order."""
    return {f.name: f.metadata["option"] for f in fields(RenderSettings)}


def settings_from_table(table: dict) -> dict:
    """``[render]`` keys (as :func:`read_render_table` returns them) as :class:`RenderSettings` field names."""
    names = {o.key: name for name, o in options().items() if o.key is not None}
    return {names[k]: v for k, v in table.items()}


def read_render_table(table: dict, where: str, error) -> dict:
    """The ``[render]`` table of a scene file checked key by key (type and range, each message naming
    ``where`` and the key), then as a whole: the keys given.  ``error``: the exception class to raise."""
    keys = {o.key: (name, o) for name, o in options().items() if o.key is not None}
    unknown = sorted(set(table) - set(keys))
    if unknown:
        raise error(f"{where}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(keys))}")
    for key, value in table.items():
        _, declared = keys[key]
        try:
            declared.check(key, value)
        except ParameterError as exc:
            raise error(f"{where}: {exc}") from None
    try:
        RenderSettings(**settings_from_table(table)).validate()
    except ParameterError as exc:
        raise error(f"{where}: {exc}") from None
    return dict(table)


def settings_record(settings: RenderSettings) -> dict:
    """The options of a render as its sidecar records them (every declared field, by name)."""
    return {name: getattr(settings, name) for name in options()}
