"""The wavefront renderer's driver: a render is a sequence of passes, each a wavefront of stages.

A pass is a few samples per pixel over a band of pixels (the whole image when it fits the ``pass_samples`` budget),
so memory is bounded by the pass, not by the sample count; its buffers list the band's pixels in spread-out blocks
(:mod:`lightprobe.integrators.schedule`), so that the threads' shares of every stage hold the same mix of sky and
objects.  The stages (:mod:`lightprobe.integrators.pipeline`) fill the pass's records
(:mod:`lightprobe.integrators.pass_state`) and end by adding each pixel's samples, in sample order, to a running mean
and variance (:mod:`lightprobe.integrators.accumulation`).

Every random number is a function of (seed, pixel, sample index, dimension) and each pixel is accumulated in sample
order, so the image is bit-identical for any pass size and any thread count.  Camera rays that miss show the
infinite lights (black without any); camera rays that hit an emitter see its radiance.  Objects cast shadows but do
not light each other (direct illumination only).

Strategies (per camera sample, ``n = n_bsdf + K n_env`` directions for the single-technique ones, so that all
strategies cost the same number of shadow rays): ``uniform`` and ``cosine`` hemisphere sampling about the shading
normal, ``brdf``, ``env`` (light sampling: K lights picked by the light sampler, ``n_env`` samples each; the
environment is one of the lights), and ``mis`` with ``n_bsdf`` BSDF and K ``n_env`` light samples weighted by the
balance or power heuristic on sample-count-weighted densities.

This module decides the rounds (one sample per pixel first; under a time limit, as many as fit; adaptive rounds
after a pilot), launches the stages of each pass, and keeps what has been accumulated on Ctrl-C or a time limit.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace

import numba
import numpy as np

from ..bsdfs.lambert import LAMBERT
from ..bsdfs.phong import PHONG
from ..emitters.area import STRATEGIES as LIGHT_STRATEGIES
from ..emitters.envmap import BILINEAR, placeholder_environment
from ..emitters.kinds import LightArrays, light_counts
from ..emitters.lights import is_delta, light_arrays
from ..emitters.selection import LightSelector, build_selector
from ..errors import LightprobeWarning, ParameterError
from ..geometry.embree import PACKET, packets_native
from ..geometry.raytracer import RayTracer
from ..geometry.shape_bvh import SHAPES_FOR_BVH
from ..geometry.shapes import Rectangle, Sphere
from ..sampling.rng import SAMPLERS
from ..scene import Scene
from ..simd import LANES
from . import adaptive, light_learning, outlines, picks, pipeline, precompile
from .accumulation import Accumulator, RenderResult, result_from
from .pass_state import PassConstants, camera_buffers, slot_buffers, views
from .schedule import pass_pixels
from .settings import DIFFUSE, HEURISTICS, RenderSettings, settings_record
from .stages import environment_lanes
from .stages.ray_lanes import FIELDS as RAY_FIELDS
from .stages.setup import SETUP_RUN
from .techniques import STRATEGIES

__all__ = [
    "STRATEGIES",
    "Accumulator",
    "RenderPlan",
    "RenderResult",
    "RenderSettings",
    "kernels_cached",
    "learns_light_selection",
    "plan_for",
    "render",
    "resolve",
    "result_from",
    "settings_for",
]

_clock = time.perf_counter  # the render's clock (time limits, seconds); tests replace it with one that ticks

# The default pass: 2^19 camera samples, and at most 2^22 shading slots.  Larger passes win up to about 2^21 slots
# (launches and Python between kernels cost less per sample); since the stages got faster, 8 slots per camera sample
# in passes of 2^19 camera samples (4.2 M slots, 1.1 GB at the peak) render the peer scene 3 % faster than in 2^18
# (0.7 GB): fewer launches, each of which starts on tables and accumulators the stage before evicted from the caches
# (decisions.md 28, 40, 51).
PASS_CAMERA_SAMPLES = 1 << 19
PASS_SLOTS = 1 << 22

#: when a dict, every stage launch adds its seconds under the stage's name (``benchmarks/peer_scene.py --profile``)
PROFILE: dict | None = None


def default_pass_samples(shading_samples: int) -> int:
    """Camera samples per pass when ``pass_samples`` is not given, for ``shading_samples`` slots each."""
    return max(1, min(PASS_CAMERA_SAMPLES, PASS_SLOTS // max(1, shading_samples)))


def lit_by_the_map_alone(scene: Scene) -> bool:
    """The environment map is the scene's only light."""
    return scene.environment is not None and not scene.emitters and not scene.lights


def _environment_alone(scene: Scene, settings: RenderSettings) -> bool:
    """The environment map is the scene's only light (and one light is picked per sample)."""
    return lit_by_the_map_alone(scene) and settings.lights_per_sample in (None, 1)


def _delta_lights(scene: Scene, table: LightArrays | None = None) -> int:
    """How many of the scene's lights are point or spot lights or delta directional lights, by the light contract's
    own test on their rows (``table``: the scene's light table, if already built; otherwise the rows of its lights
    alone), run as Python (no kernel to load for a count)."""
    if not scene.lights:
        return 0
    table = table if table is not None else light_arrays(scene.lights)
    return sum(bool(is_delta.py_func(table, i)) for i in range(table.kind.shape[0]))


def settings_for(scene: Scene, settings: RenderSettings, resumed: bool = False) -> RenderSettings:
    """``settings`` with the automatic choices made as :func:`render` makes them for ``scene`` (``resumed``: a
    render that continues another), the number of light picks included where a probe chooses it
    (integrators/picks.py: then this renders the probe, a second or two)."""
    resolved = _settings_for(scene, settings, _environment_alone(scene, settings), _delta_lights(scene), resumed)
    if not picks.probes(scene, settings, resolved):
        return resolved
    plan = resolve(scene, settings, resumed=resumed)
    arrays = scene.compile()
    tracer = RayTracer(arrays, threads=numba.get_num_threads())
    try:
        return _probed(scene, plan, arrays, tracer, numba.get_num_threads(), precompile.Helpers())[0].settings
    finally:
        tracer.close()


def _settings_for(scene: Scene, settings: RenderSettings, alone: bool, delta_lights: int, resumed: bool):
    """:func:`settings_for` from what the scene's lights have already been found to be.  A scene whose only light
    is a delta light (point, spot, directional of angle 0) takes one pick: every sample of it is the same direction."""
    one_delta_light = scene.environment is None and not scene.emitters and len(scene.lights) == 1 and delta_lights == 1
    return settings.resolved(
        environment_only=alone,
        one_delta_light=one_delta_light,
        environment=scene.environment is not None,
        resumed=resumed,
        bounded_lights=scene.bounded_light_count,
    )


def compensation_for(scene: Scene, settings: RenderSettings) -> bool | str:
    """Which materials sample the MIS-compensated environment (True: all, False: none, ``DIFFUSE``: Lambertian ones),
    for resolved ``settings``: automatically the Lambertian ones under MIS wherever the scene has a map (decisions.md
    21, 29 and 98), if there are BSDF samples to find the dim texels the compensated density leaves out (without
    them the demo lost 16 % of its light)."""
    if settings.mis_compensation is not None:
        return settings.mis_compensation
    automatic = settings.strategy == "mis" and settings.n_bsdf > 0 and scene.environment is not None
    return DIFFUSE if automatic else False


def _checked(settings: RenderSettings, resolved: RenderSettings) -> RenderSettings:
    """The ``resolved`` settings, checked again: the automatic counts may take the slots past 64, and then the
    message says which counts were left automatic and what they came to (numbers the user never typed)."""
    try:
        resolved.validate()
    except ParameterError as exc:
        auto = [name for name in ("n_bsdf", "n_env", "lights_per_sample") if getattr(settings, name) is None]
        if not auto:
            raise
        chosen = ", ".join(f"{name} = {getattr(resolved, name)}" for name in auto)
        raise ParameterError(f"{exc} (automatic for this scene: {chosen})") from None
    return resolved


def plan_for(scene: Scene, settings: RenderSettings) -> pipeline.Plan:
    """What a render of ``scene`` with ``settings`` needs, and so its stages."""
    alone = _environment_alone(scene, settings)
    k = scene.environment.kernel if scene.environment is not None else None
    lanes = environment_lanes.compiles()
    return pipeline.Plan(
        environment_alone=alone,
        bounded_lights=scene.bounded_light_count > 0,
        emissive_surfaces=bool(scene.emitters),
        meshes=scene.triangle_count > 0,
        resampled=settings.env_candidates > 1,
        lanes=lanes,
        environment_samples_in_lanes=alone and environment_lanes.samples_apply(k),
        environment_coords_in_lanes=alone and environment_lanes.coords_apply(k),
        environment_radiance_in_lanes=alone and environment_lanes.applies(k.image, k.lookup == BILINEAR),
        packets=packets_native(),
        textured=any(material.textures is not None for material in scene.materials.values()),
        shape_tree=sum(isinstance(o.shape, Sphere | Rectangle) for o in scene.objects) > SHAPES_FOR_BVH,
    )


@dataclass(frozen=True)
class RenderPlan:
    """What a render works out from its scene and settings, once (:func:`resolve`), for the driver, its statistics
    and the laboratory to read: the settings checked and with their automatic choices made, the light table and its
    selector, how many delta lights there are, which materials sample the compensated map, and the stages (whether
    the environment map is the only light: ``pipeline.environment_alone``)."""

    settings: RenderSettings  # resolved and checked
    lights: LightArrays  # the scene's light table (emitters/table.py)
    selector: LightSelector  # the resolved light sampler over it
    delta_lights: int  # point and spot lights and directional lights of angle 0
    compensated: bool | str  # compensation_for: True, False or DIFFUSE
    pipeline: pipeline.Plan  # what the scene needs, and so the stages
    # the render chooses its light picks (settings.lights_per_sample, until then MANY_LIGHTS_PICKS) by a probe
    # (integrators/picks.py); settings_for makes the same choice
    probe_picks: bool = False


def resolve(scene: Scene, settings: RenderSettings | None = None, *, resumed: bool = False) -> RenderPlan:
    """The :class:`RenderPlan` of a render of ``scene`` with ``settings`` (``resumed``: one that continues
    another): the settings checked as given (a user's value named as typed), resolved for the scene, and checked
    again with the automatic counts in the message; the light table built once, and its selector."""
    settings = settings or RenderSettings()
    settings.validate()
    alone = _environment_alone(scene, settings)
    _check(scene, settings, alone)
    lights = scene.light_table()
    delta_lights = _delta_lights(scene, lights)
    resolved = _checked(settings, _settings_for(scene, settings, alone, delta_lights, resumed))
    environment = scene.environment
    return RenderPlan(
        settings=resolved,
        lights=lights,
        selector=build_selector(
            resolved.light_sampler,
            lights,
            env_irradiance=environment.irradiance_terms if environment is not None else None,
            env_irradiance_compensated=environment.compensated_irradiance_terms if environment is not None else None,
        ),
        delta_lights=delta_lights,
        compensated=compensation_for(scene, resolved),
        pipeline=plan_for(scene, resolved),  # the stages follow the resolved pick count
        probe_picks=picks.probes(scene, settings, resolved),
    )


def _probed(
    scene, render_plan: RenderPlan, arrays, tracer, threads, helpers: precompile.Helpers
) -> tuple[RenderPlan, dict, dict]:
    """(``render_plan`` with its light picks chosen by the probe of integrators/picks.py, what the probe found, the
    outline fields it worked out for the render's own pass):
    a learned selection learned once, from ``light_learning.UNIFORM_PILOT`` samples of the probe's pixels with the
    largest K; then, for each candidate K, the probe's pixels at ``picks.PROBE_SPP`` samples with each of
    ``picks.PROBE_SEEDS`` (uniform counts, picking with what was learned), the relMSE between the two images, and
    the K of highest efficiency.  The first render compiles the stages here (``helpers``: its compile helpers, as
    :func:`_render_planned`'s); the seconds are the probe's alone."""
    settings = render_plan.settings
    width, height = scene.camera.resolution
    n_pixels = width * height
    pixels, stride = picks.probe_pixels(width, height)
    fields = outlines.pass_fields(scene.camera, render_plan.lights, tracer, settings.outline_control_variate)
    ks = picks.candidates(settings)
    buffers, learned = None, None

    def probe_pass(k: int, seed: int, spp: int) -> _Pass:
        nonlocal buffers
        probe_settings = replace(
            settings, lights_per_sample=k, seed=seed, spp=spp, first_sample=0, adaptive=False, time_limit=None
        )
        # the same stages: K > 1 picks leave them as they are (plan_for)
        work = _Pass(
            scene,
            replace(render_plan, settings=probe_settings),
            arrays,
            tracer,
            pixels.size * spp,
            threads,
            learned=learned,
            outline_fields=fields,
            record_stride=stride,
        )
        if buffers is None:  # made once, for the largest K: every other pass uses leading views of them
            work.make_buffers()
            buffers = work.cams, work.slots
        work.cams, work.slots = buffers
        return work

    pilot = light_learning.UNIFORM_PILOT
    work = probe_pass(max(ks), picks.PROBE_SEEDS[0], max(picks.PROBE_SPP, pilot + 1))
    _warm_up(work, n_pixels, helpers)
    start = _clock()
    if work.learning is not None:
        work.run(Accumulator(n_pixels), pixels, pilot, 0)
        work.learn()
        learned = work.learned
    errors = {}
    for k in ks:
        images = []
        for seed in picks.PROBE_SEEDS:
            acc = Accumulator(n_pixels)
            probe_pass(k, seed, picks.PROBE_SPP).run(acc, pixels, picks.PROBE_SPP, 0)
            images.append(acc.mean[pixels])
        errors[k] = picks.relmse(*images)
    k = picks.chosen(errors)
    plan = replace(render_plan, settings=replace(settings, lights_per_sample=k), probe_picks=False)
    found = {"relmse": {str(key): e for key, e in errors.items()}, "pixels": int(pixels.size), "chosen": k}
    return plan, {**found, "seconds": _clock() - start}, fields


def _warm_up(work: _Pass, n_pixels: int, helpers: precompile.Helpers) -> None:
    """Every stage of ``work`` run on one pixel: loads their cached machine code, or compiles it (a first render of
    this kind, with helper processes compiling some of the stages beside it: precompile.py, started here unless
    :func:`_start_helpers_early` did); then the helpers are stopped."""
    plan = work.plan
    try:
        if not _stages_cached(plan):
            records = work.records(Accumulator(n_pixels), pass_pixels(0, 1), 1, 0)
            signatures = precompile.record_types_pickled(records)
            precompile.save_record_types(signatures)  # for the next render's early helpers
            helpers.start(plan.stages(), signatures)
            if work.learning is not None:  # its kernels now, beside the helpers, not in the pilot's first passes
                work.learning.compile_kernels(records)
            work.launcher.prepare(work.stages, records, helpers if helpers.started else None)
        work.run(Accumulator(n_pixels), pass_pixels(0, 1), 1, 0)
    finally:
        helpers.stop()


def _start_helpers_early(scene: Scene, settings: RenderSettings | None, helpers: precompile.Helpers) -> None:
    """Start a first render's compile helpers before the scene's light table, selector and outlines are built
    (their kernels compile in this process meanwhile), where an earlier render of these sources kept the pass
    records' types: the many-light demo after the demo compiled for about 20 s before its warm-up (decisions.md
    129).  The stages are those of :func:`plan_for` with the settings as given; where :func:`resolve` then changes
    the plan, the render compiles what the helpers did not."""
    if precompile.helpers_wanted(2) == 0:
        return
    signatures = precompile.known_record_types()
    if signatures is None and not helpers.waiting:  # a prestarted helper works the types out itself
        return
    settings = settings or RenderSettings()
    settings.validate()  # resolve's first checks: a user's error is reported as it would be without helpers
    _check(scene, settings, _environment_alone(scene, settings))
    plan = plan_for(scene, settings)
    if not _stages_cached(plan):
        helpers.start(plan.stages(), signatures)


def learns_light_selection(scene: Scene, settings: RenderSettings | None = None) -> bool:
    """Whether a render of ``scene`` with ``settings`` can learn its light selection (``light_sampler`` learned,
    light samples taken, two bounded lights or more: ``light_learning.learns``); it does so from its first samples
    (``light_learning.pilot_for``) where it has more than those."""
    plan = resolve(scene, settings)
    return light_learning.learns(plan.selector, plan.settings.strategy, plan.settings.light_sampler)


def _check(scene: Scene, settings: RenderSettings, alone: bool) -> None:
    if settings.strategy == "mis":
        for name, bsdf in scene.materials.items():
            if bsdf.kind == PHONG and getattr(bsdf, "estimator", "mixture") != "mixture":
                raise ParameterError(f"material {name!r}: MIS needs Phong's mixture estimator (seed eq. 19)")
    if not alone and settings.env_candidates > 1:
        raise ParameterError("env_candidates applies to scenes lit by an environment map alone")
    if settings.mis_compensation and scene.environment is None:
        raise ParameterError("mis_compensation applies to environment maps: this scene has none")
    if settings.mis_compensation and settings.n_bsdf == 0:
        raise ParameterError(
            "mis_compensation needs BSDF samples (n_bsdf >= 1): the compensated PDF is zero on dim texels, whose "
            "light only BSDF samples find"
        )


def _warn_of_unreached_delta_lights(plan: RenderPlan) -> None:
    """A point, spot or delta directional light is reached by light samples only (no direction of another technique
    is ever exactly its one): a render that takes none -- BSDF, cosine or uniform sampling, or MIS with no light
    samples -- leaves such lights out of the image, as the estimator defines, but a user may not expect it.  Said
    once per render, as a warning (the laboratory compares such strategies on purpose)."""
    settings = plan.settings
    takes_none = settings.strategy in ("brdf", "cosine", "uniform") or (
        settings.strategy == "mis" and settings.n_env == 0
    )
    delta = plan.delta_lights if takes_none else 0
    if delta:
        why = f"strategy {settings.strategy!r}" if settings.strategy != "mis" else "env_samples = 0"
        one = delta == 1
        warnings.warn(
            f"{delta} delta light{'' if one else 's'} (point, spot or directional of angle 0) "
            f"light{'s' if one else ''} nothing in this render: only light samples reach "
            f"{'it' if one else 'them'}, and {why} takes none",
            LightprobeWarning,
            stacklevel=3,
        )


def _compensated_materials(kinds: np.ndarray, compensated) -> np.ndarray:
    """Per material, whether its environment samples (and the MIS weights of its BSDF samples) use the compensated
    PDF: every material for True, none for False, Lambertian ones for ``DIFFUSE``.  Both techniques at a shading
    point see the same density, so each point's MIS weights still sum to one (Veach 1997, 9.2)."""
    if compensated == DIFFUSE:
        return np.ascontiguousarray(kinds == LAMBERT)
    return np.full(kinds.shape[0], bool(compensated))


class _Pass:
    """One render's stages and buffers: :meth:`run` renders one pass into an accumulator."""

    def __init__(
        self,
        scene,
        render_plan: RenderPlan,
        arrays,
        tracer,
        largest_pass,
        threads,
        resumed=None,
        learned=None,
        *,
        outline_fields: dict | None = None,
        record_stride: int | None = None,
    ):
        """``outline_fields``: ``outlines.pass_fields`` already worked out for this render (the probe's passes
        share them); ``record_stride``: the render samples every ``record_stride``-th pixel alone (the probe), and
        a learned selection records all of them."""
        threads_max = max(threads, numba.config.NUMBA_NUM_THREADS)
        settings, plan = render_plan.settings, render_plan.pipeline
        self.plan = plan
        self.stages = tuple(pipeline.stage_id(name) for name in plan.stages())
        self.names = plan.stages()
        m = settings.shading_samples
        lights = render_plan.lights
        self.scene = arrays
        self.env = (scene.environment or placeholder_environment()).kernel
        self.lights = lights
        self.sel = render_plan.selector
        self.ray_counts = np.zeros((threads_max, 8), np.int64)  # per worker (a row = a cache line)
        self.launcher = pipeline.Launcher(threads)
        compensated = render_plan.compensated
        self.compensated = compensated
        self.constants = PassConstants(
            sampler=SAMPLERS[settings.sampler],
            seed=settings.seed,
            strategy=STRATEGIES[settings.strategy],
            n_bsdf=settings.n_bsdf,
            n_light=settings.light_samples,
            n_per_light=settings.n_env,
            m=m,
            beta=HEURISTICS[settings.heuristic],
            light_strategy=LIGHT_STRATEGIES[settings.light_strategy],
            env_candidates=settings.env_candidates,
            bsdf_weighed=not plan.environment_alone,
            compensate=_compensated_materials(arrays.material_kind, compensated),
            cam=scene.camera.kernel_array(),
            mesh_scene=tracer.mesh_scene,
            scratch=tracer.scratch,
            ray_counts=self.ray_counts,
            # a run of camera samples' Sobol' numbers, per thread (stages/setup.py; rows of whole cache lines: 8
            # slots x 24 bytes)
            numbers=np.zeros((threads_max, (SETUP_RUN * m + LANES - 1) // LANES * LANES, 3)),
            packet_slots=np.zeros((threads_max, max(PACKET, LANES)), np.int64),
            lane_rays=np.zeros((threads_max, RAY_FIELDS, LANES)),
            pixels=np.zeros(0, np.int64),
            spp_pass=1,
            sample_start=0,
            **(outline_fields or outlines.pass_fields(scene.camera, lights, tracer, settings.outline_control_variate)),
        )
        self.m = m
        self.largest = largest_pass
        self.cams = None
        self.slots = None
        self.learning = None  # light_learning.Learning of a render that learns its light selection ...
        self.learned = None  # ... and what a render's light selection learned (or continues), for its statistics
        if light_learning.learns(self.sel, settings.strategy, settings.light_sampler):
            pilot = light_learning.pilot_for(settings.spp, settings.adaptive)
            if resumed is not None and resumed.learned is not None:
                learned = resumed.learned
            if learned is not None:
                self.sel = light_learning.restored(self.sel, learned)
                self.learned = learned
            elif settings.first_sample == 0 and pilot < settings.spp and (settings.adaptive or not settings.time_limit):
                n_pixels = int(np.prod(scene.camera.resolution))
                self.learning = light_learning.Learning(
                    self.sel, n_pixels, pilot, self.constants.strategy, settings.n_bsdf, m, stride=record_stride
                )
                self.sel = self.learning.selector

    def make_buffers(self) -> None:
        """Every pass uses leading views of these: memory bounded by one pass.  (Mapped without huge pages, and
        populated when mapped: first touches in the first passes took up to twice a pass's time, decisions.md 32,
        39.)"""
        self.cams = camera_buffers(self.largest, textured=bool(self.scene.material_textured.any()))
        self.slots = slot_buffers(
            self.largest * self.m,
            picks=not self.plan.environment_alone,
            bounded_shadows=self.plan.bounded_lights,
            bsdf_hits=self.plan.emissive_surfaces,
            learning=self.learning is not None,
        )

    def records(self, acc: Accumulator, pixels: np.ndarray, spp_now: int, sample_start: int) -> tuple:
        """The stages' records for a pass over ``pixels`` x ``spp_now`` samples into ``acc``."""
        n = pixels.size * spp_now
        cams, slots = views(self.cams, n), views(self.slots, n * self.m)
        if self.learning is not None and not self.learning.recording:
            slots = slots._replace(learn=slots.learn[:0])  # learned: no more records
        c = self.constants._replace(pixels=pixels, spp_pass=spp_now, sample_start=sample_start)
        return self.scene, self.env, self.lights, self.sel, c, cams, slots, acc.arrays()

    def run(self, acc: Accumulator, pixels: np.ndarray, spp_now: int, sample_start: int) -> int:
        """One pass over ``pixels`` x ``spp_now`` samples into ``acc``; returns the number of shadow rays traced."""
        records = self.records(acc, pixels, spp_now, sample_start)
        for stage, name in zip(self.stages, self.names, strict=True):
            if PROFILE is None:
                self.launcher.run(stage, records)
                continue
            start = time.perf_counter()
            self.launcher.run(stage, records)
            PROFILE[name] = PROFILE.get(name, 0.0) + time.perf_counter() - start
        if self.learning is not None:
            self.learning.record(records)
        return int(np.count_nonzero(records[6].flags))  # the slots'

    def learn(self) -> None:
        """After the pilot: the light selection learned from its records, for every later pass."""
        if self.learning is not None and self.learning.recording:
            self.sel = self.learning.learn()
            self.learned = light_learning.table_of(self.sel)


def render(
    scene: Scene,
    settings: RenderSettings | None = None,
    *,
    progress: Callable[[dict], None] | None = None,
    tracer: RayTracer | None = None,
    resume: Accumulator | None = None,
    learned: dict | None = None,
) -> RenderResult:
    """Render ``scene``; ``progress(stats)`` is called after every pass.  Ctrl-C keeps what has been accumulated
    (``stats['interrupted']``), as does a time limit (``stats['stopped_by_time_limit']``).  ``resume``: continue
    these statistics (a copy) with samples ``settings.first_sample`` onward; resuming where a render stopped gives
    the same bits as an uninterrupted render.  ``learned``: the light selection a render of the samples before
    ``settings.first_sample`` learned (its ``accumulator.learned``), for a sample range rendered apart from them
    (``analysis/distributed.py``): it picks as the whole render would (``resume``'s, if it carries one, wins)."""
    t_setup = time.perf_counter()
    helpers = precompile.take_prestarted()  # processes compiling some of the stages of a first render of this kind
    callers_threads = numba.get_num_threads()  # given back after the render: its thread count is its own
    try:
        _start_helpers_early(scene, settings, helpers)
        render_plan = resolve(scene, settings, resumed=resume is not None)
        if render_plan.settings.threads is not None:
            numba.set_num_threads(min(render_plan.settings.threads, numba.config.NUMBA_NUM_THREADS))
        threads = numba.get_num_threads()
        _warn_of_unreached_delta_lights(render_plan)
        return _render_planned(scene, render_plan, helpers, progress, tracer, resume, threads, t_setup, learned)
    finally:
        numba.set_num_threads(callers_threads)
        helpers.stop()


def _render_planned(scene, render_plan, helpers, progress, tracer, resume, threads, t_setup, learned) -> RenderResult:
    """:func:`render` of its :class:`RenderPlan`; ``helpers``: the processes compiling some of its stages (started
    early, or by its warm-up), which it stops once its own warm-up has compiled (or loaded) them all."""
    arrays = scene.compile()
    own_tracer = tracer is None
    tracer = tracer or RayTracer(arrays, threads=threads)
    probe, outline_fields = None, None
    if render_plan.probe_picks:
        render_plan, probe, outline_fields = _probed(scene, render_plan, arrays, tracer, threads, helpers)
    settings = render_plan.settings
    width, height = scene.camera.resolution
    n_pixels = width * height
    m = settings.shading_samples
    pass_samples = settings.pass_samples or default_pass_samples(m)
    spp_pass = max(1, min(settings.spp, pass_samples // n_pixels))
    band = max(1, min(n_pixels, pass_samples // spp_pass))
    if resume is not None and settings.adaptive:
        raise ParameterError("an adaptive render cannot be resumed: its sample counts need the whole pilot first")
    if resume is not None and resume.count.size != n_pixels:
        raise ParameterError(f"cannot resume a render of {resume.count.size} pixels at {width}x{height}")
    if resume is not None and (problem := resume.resume_problem(settings.first_sample)) is not None:
        raise ParameterError(problem)
    acc = resume.copy() if resume is not None else Accumulator(n_pixels)
    acc.adaptive = settings.adaptive  # resolved: a continued render is uniform (or refused above)
    plan = render_plan.pipeline
    largest_pass = max(1, band * spp_pass)
    work = _Pass(
        scene, render_plan, arrays, tracer, largest_pass, threads, resume, learned, outline_fields=outline_fields
    )
    kinds = work.lights.kind
    stats = {
        "width": width,
        "height": height,
        "spp_requested": settings.spp,
        **{k: v for k, v in settings_record(settings).items() if k not in ("spp", "time_limit", "pass_samples")},
        "mis_compensation": work.compensated,
        # pixels where the outline control variate knows an emitter's share (integrators/outlines.py)
        "outline_pixels": int(np.count_nonzero(np.diff(work.constants.outline_start))),
        **light_counts(kinds),
        "stages": list(plan.stages()),
        "threads": threads,
        "spp_per_pass": spp_pass,
        "camera_rays": 0,
        "shadow_rays": 0,
        "embree_rays": 0,
        "passes": 0,
        "interrupted": False,
        "stopped_by_time_limit": False,
        "triangles": scene.triangle_count,
    }
    if probe is not None:
        stats["picks_probe"] = probe
    stats["time_limit"] = settings.time_limit

    def over_image(sample_start: int, spp_now: int):
        """The passes that give every pixel samples sample_start .. sample_start + spp_now - 1."""
        for pixel_start in range(0, n_pixels, band):
            count = min(band, n_pixels - pixel_start)
            yield pass_pixels(pixel_start, count), spp_now, sample_start, pixel_start + count

    def uniform_passes(first: int, spp: int):
        for sample_start, spp_now in _sample_rounds(first, spp, spp_pass):
            yield from over_image(sample_start, spp_now)

    def timed_uniform_passes(first: int, spp: int):
        """The uniform rounds under a time limit, each sized from the time per sample per pixel of the round
        before so that the render ends at the limit, not up to a whole pass after it: a round takes the samples
        that fit in the time left (rounded to the nearest), and none are left once half of one no longer fits.
        The image is the one the same samples give in any rounds: only how many there are follows the clock."""
        round_start = _clock()
        yield from over_image(first, 1)  # every pixel gets a sample before the clock can stop the render
        per_spp = _clock() - round_start
        sample, end = first + 1, first + spp
        while sample < end:
            round_start = _clock()
            left = settings.time_limit - (round_start - start)
            spp_now = min(spp_pass, end - sample, int(left / max(per_spp, 1e-9) + 0.5))
            if spp_now < 1:
                stats["stopped_by_time_limit"] = True
                return
            yield from over_image(sample, spp_now)
            per_spp = (_clock() - round_start) / spp_now
            sample += spp_now

    def passes():
        """(pixels, samples per pixel, first sample index, pixels done) of every pass, in order: the uniform rounds
        over the image (of the pilot, if adaptive), then the adaptive rounds (integrators/adaptive.py).  The
        generator runs as the passes are made, so it sees the time spent and the pilot's statistics."""
        if not settings.adaptive:
            if work.learning is not None:  # learned light selection: from the first samples, for the rest
                pilot = light_learning.UNIFORM_PILOT
                yield from uniform_passes(0, pilot)
                work.learn()
                yield from uniform_passes(pilot, settings.spp - pilot)
                return
            rounds = uniform_passes if settings.time_limit is None else timed_uniform_passes
            yield from rounds(settings.first_sample, settings.spp)
            return
        pilot, replan = adaptive.pilot_spp(settings.spp), None
        if settings.time_limit is None:
            if work.learning is not None:  # the pilot's first half learns the light selection for the rest
                learned_at = light_learning.pilot_for(settings.spp, True)
                yield from uniform_passes(0, learned_at)
                work.learn()
                yield from uniform_passes(learned_at, pilot - learned_at)
            else:
                yield from uniform_passes(0, pilot)
            counts = adaptive.sample_counts(acc.mean, acc.m2, acc.count, width, height, settings.spp)
        else:  # a time budget: the pilot doubles while it fits in a share of it, then the rest buys the counts
            pilot, round_start = 1, _clock()
            yield from uniform_passes(0, 1)
            while adaptive.time_pilot_continues(pilot, settings.spp, _clock() - start, settings.time_limit):
                round_start = _clock()
                for sample_start in range(pilot, 2 * pilot, spp_pass):  # samples pilot .. 2 pilot - 1
                    yield from over_image(sample_start, min(spp_pass, 2 * pilot - sample_start))
                pilot *= 2
            work.learn()
            # time per sample per pixel from the pilot's last round, the one in full-sized passes
            per_spp = (_clock() - round_start) / max(1, pilot // 2)
            mean_spp = adaptive.budget_mean(pilot, settings.spp, _clock() - start, settings.time_limit, per_spp)
            w = adaptive.relative_noise(acc.mean, acc.m2, acc.count, width, height)
            counts = adaptive.counts_from_noise(w, pilot, mean_spp)
            stats["adaptive_mean_planned"] = mean_spp
            stats["adaptive_pilot_seconds"], stats["adaptive_seconds_per_spp"] = _clock() - start, per_spp
            rounds_start = _clock()

            def replan(done: np.ndarray) -> np.ndarray:
                """The counts again, at the time per camera sample the rounds after the pilot have taken: the
                pilot's price for them (x COST_FACTOR) was only a first guess."""
                affordable = (settings.time_limit - (_clock() - start)) * taken / max(_clock() - rounds_start, 1e-9)
                planned = adaptive.counts_from_noise(w, pilot, settings.spp, done, max(0.0, affordable))
                stats["adaptive_max_spp"] = int(planned.max())
                return planned

        # the plan's largest count (the image's own is spp_max: they differ if the render stops early)
        stats["adaptive_pilot_spp"], stats["adaptive_max_spp"] = pilot, int(counts.max())
        taken = 0  # camera samples after the pilot
        for pixels, spp_now, sample_start in adaptive.sample_rounds(counts, pilot, largest_pass, replan):
            yield pixels, spp_now, sample_start, n_pixels
            taken += pixels.size * spp_now

    counted_before = 0
    start = _clock()
    with _InterruptAtPassEnd() as interrupt:
        try:
            # made under the Ctrl-C handler: populating their pages can take a second or more per GB on this VM,
            # and a Ctrl-C meanwhile waits for the first pass like any other
            work.make_buffers()
            _warm_up(work, n_pixels, helpers)  # before the clock starts
            if settings.adaptive:
                adaptive.warm_up()
            if PROFILE is not None:
                PROFILE.clear()  # the warm-up (and any compiling) is not the render
            counted_before = work.ray_counts.sum()
            # the probe's seconds are the render's (its efficiency pays for them), not its setup's
            probe_seconds = probe["seconds"] if probe is not None else 0.0
            stats["setup_seconds"] = max(0.0, time.perf_counter() - t_setup - probe_seconds)
            start = _clock() - probe_seconds
            for pixels, spp_now, sample_start, pixels_done in passes():
                stats["shadow_rays"] += work.run(acc, pixels, spp_now, sample_start)
                stats["camera_rays"] += pixels.size * spp_now
                stats["passes"] += 1
                stats["seconds"] = _clock() - start
                stats["spp_done"] = int(acc.count.min())
                if progress is not None:
                    progress(dict(stats, spp_target=settings.spp, pixels_done=pixels_done))
                if stats["spp_done"] < 1:
                    continue  # a stop waits until every pixel holds a sample (the first round is 1 spp)
                if interrupt.requested:
                    raise KeyboardInterrupt
                if settings.time_limit is not None and stats["seconds"] >= settings.time_limit:
                    stats["stopped_by_time_limit"] = True
                    raise _Stop
        except _Stop:
            pass  # pixels of the unfinished pass have one pass fewer: their counts say so
        except KeyboardInterrupt:
            stats["interrupted"] = True
    stats["seconds"] = _clock() - start
    if work.learned is not None:  # a continued render learns what the render that did not stop learned
        acc.learned = work.learned
        stats["learned_levels"] = int(work.learned["cut_levels"])
        stats["learned_cells"] = light_learning.cells_learned(work.learned)
    stats["embree_rays"] = int(work.ray_counts.sum() - counted_before)  # every Embree call of a render is in a stage
    if own_tracer:
        tracer.close()
    return _finish(acc, stats, width, height)


def kernels_cached(scene: Scene | None = None, settings: RenderSettings | None = None) -> bool:
    """Whether the stage loop and the stage bodies of a render of ``scene`` with ``settings`` (the demo's, by
    default) are in the on-disk cache; else that render compiles them first.  The loop is one for every plan, each
    plan runs its own bodies (:func:`pipeline.run_stage`); the pass records have the same types whatever they hold
    (``pass_state.py``)."""
    if scene is None:
        from ..demo import demo_scene

        scene = demo_scene((8, 5))
    return _stages_cached(plan_for(scene, settings or RenderSettings()))


def _stages_cached(plan: pipeline.Plan) -> bool:
    """Whether the stage loop and the bodies of ``plan``'s stages are in the on-disk cache."""
    from .._numba import is_cached

    return is_cached(pipeline.run_stage, *(pipeline.STAGES[pipeline.stage_id(n)].body for n in plan.stages()))


class _Stop(Exception):
    """The time limit was reached."""


def _sample_rounds(first: int, spp: int, spp_pass: int):
    """(first sample index, samples per pixel) of each round over the image: one sample first, so that a stop
    (Ctrl-C, a time limit) soon after the start still leaves every pixel with a sample, then ``spp_pass`` at a
    time.  The rounds change nothing in the image: each sample's random numbers depend on its index alone."""
    yield first, 1
    for start in range(1, spp, spp_pass):
        yield first + start, min(spp_pass, spp - start)


class _InterruptAtPassEnd:
    """While rendering in the main thread, the first Ctrl-C asks the render to stop at the end of the pass in
    flight (no finished work is thrown away, and never before every pixel has a sample); a second Ctrl-C
    interrupts at once, keeping what has been accumulated.  Elsewhere (a worker thread) Ctrl-C is left alone."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def _handler(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __enter__(self):
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc):
        import signal

        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False


def _finish(acc: Accumulator, stats: dict, width: int, height: int) -> RenderResult:
    counts = acc.count
    samples = int(counts.sum())
    seconds = max(stats.get("seconds", 0.0), 1e-12)
    rays = stats["camera_rays"] + stats["shadow_rays"]
    stats.update(
        spp_done=int(counts.min()),
        spp_max=int(counts.max()),
        spp_mean=samples / max(counts.size, 1),  # adaptive counts: spp on average
        camera_samples=samples,
        samples_per_s=samples / seconds,
        rays=rays,
        rays_per_s=rays / seconds,
        nonfinite_samples=int(acc.nonfinite.sum()),
    )
    return result_from(acc, width, height, stats)
