"""Render a scene with user techniques: the laboratory's estimator, one batch of shading points at a time.

A :class:`LabStrategy` is one technique alone (``n_bsdf + n_env`` directions of it per camera sample, as the
renderer's single-technique strategies) or two under MIS, a BSDF technique and a light technique (``n_bsdf`` and
``n_env`` directions), weighted by a heuristic (balance, power, or the user's own function). Either technique may be
lightprobe's own (:func:`~lightprobe.lab.techniques.builtin`) or a user's. Per camera sample, with f the scene's
material and L the environment (Krivanek eqs. 2 and 16)::

    value = sum over techniques t, samples i of  w_t(wi) f(wo, wi) cos(theta_i) L(wi) V(wi) / (n_t p_t(wi))

What follows the techniques' directions (f, the factor w cos / (n p), the shadow rays, the sum in the core's order)
is :mod:`lightprobe.integrators.batch_estimator`'s, the one place it is written beside the stages (the shading-point
tables use it too). The scene must be lit by its environment map alone (the exercise's setting; a scene with other
lights renders with a light selector instead: :mod:`lightprobe.lab.light_render`). Camera rays, hit
points and shading frames come from the render core's own routines (``store_shading_frame``), shadow rays from its
ray tracer (``RayTracer.occluded``, origins offset as the core does), random numbers from its samplers: a pure
function of (seed, pixel, sample index, dimension). Each pass is one sample of every pixel, added in sample order to the
core's :class:`~lightprobe.integrators.accumulation.Accumulator`, so the image is the same bit for bit whether it is
rendered at once or continued (``resume``), and ``compare`` can treat it like any render. A technique that fails
mid-render raises a :class:`LabRenderError` that carries what was accumulated before the failing pass.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass

import numpy as np
from numba.core.dispatcher import Dispatcher

from .._numba import jit, jit_parallel, prange
from ..geometry.intersect import MISS
from ..geometry.raytracer import RayTracer
from ..integrators.accumulation import Accumulator, RenderResult, result_from
from ..integrators.batch_estimator import Context, add_samples, shade
from ..integrators.settings import RenderSettings
from ..sampling.mis import balance_heuristic, power_heuristic
from ..sampling.rng import SAMPLERS, sampler_batch
from .camera_samples import camera_batch, require_untextured, shading_batch, technique_numbers
from .jit_techniques import (
    HEURISTICS,
    JitContext,
    KernelMaterial,
    balance_weight,
    borrowed,
    builtin_bsdf_pdf,
    builtin_bsdf_sample,
    builtin_env_pdf,
    builtin_env_sample,
    elapsed_check,
    environment_record,
    material_record,
    power_weight,
    run_rows,
    user_inline,
)
from .jit_techniques import user_serial as _user_serial
from .technique_errors import _RenderTimeUp
from .techniques import UNIT_TOLERANCE, GuardedTechnique, Heuristic, RenderClock, TechniqueError

__all__ = ["LabRenderError", "LabStrategy", "render_lab"]

#: camera samples per batch (memory: about 2 kB each with 8 directions)
BATCH = 1 << 15


class LabRenderError(TechniqueError):
    """A technique failed during a render; ``result`` holds the samples accumulated before the failing pass."""

    def __init__(self, message: str, result: RenderResult | None):
        super().__init__(message)
        self.result = result


@dataclass
class LabStrategy:
    """One technique alone, or a BSDF and a light technique under MIS with ``heuristic`` (a name or a function
    weight(n_f, p_f, n_g, p_g)); None: the render settings' heuristic."""

    techniques: tuple[GuardedTechnique, ...]
    heuristic: str | Heuristic | None = None

    def __post_init__(self):
        kinds = [t.kind for t in self.techniques]
        if len(self.techniques) == 2 and sorted(kinds) != ["bsdf", "light"]:
            raise TechniqueError(f"MIS combines a BSDF technique and a light technique, got {kinds}")
        if len(self.techniques) not in (1, 2):
            raise TechniqueError(f"a strategy has one technique or two under MIS, got {len(self.techniques)}")

    @property
    def label(self) -> str:
        names = "+".join(t.label for t in self.techniques)
        return f"mis:{names}" if len(self.techniques) == 2 else names

    def counts(self, settings: RenderSettings) -> list[int]:
        """Directions per camera sample of each technique."""
        if len(self.techniques) == 1:
            return [settings.n_bsdf + settings.light_samples]
        return [settings.n_bsdf if t.kind == "bsdf" else settings.light_samples for t in self.techniques]


def _weight(heuristic, n_f, p_f, n_g, p_g) -> np.ndarray:
    if heuristic == "balance":
        return balance_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)
    if heuristic == "power":
        return power_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)
    name = getattr(heuristic, "__name__", "the heuristic")
    if isinstance(heuristic, Dispatcher):  # an njit heuristic takes one sample's numbers
        w = np.empty(len(p_f))
        try:
            run_rows(_heuristic_rows, len(p_f), heuristic, float(n_f), p_f, float(n_g), p_g, w)
        except Exception as exc:  # the user's code
            raise TechniqueError(f"{name} raised {type(exc).__name__}: {exc} (check: MIS weights)") from None
    else:
        try:
            w = np.asarray(heuristic(n_f, p_f, n_g, p_g), dtype=np.float64)
        except (Exception, SystemExit) as exc:  # the user's code; a sys.exit() in it must not end lightprobe
            raise TechniqueError(f"{name} raised {type(exc).__name__}: {exc} (check: MIS weights)") from None
    if w.shape != np.shape(p_f) or not np.all(np.isfinite(w)) or np.any(w < 0) or np.any(w > 1 + 1e-9):
        raise TechniqueError(f"{name}: returned weights outside [0, 1], not finite or of shape {w.shape} (expected "
                             f"{np.shape(p_f)}) (check: MIS weights)")  # fmt: skip
    return w


@_user_serial
def _heuristic_rows(lo, hi, heuristic, n_f, p_f, n_g, p_g, out):
    for i in range(lo, hi):
        out[i] = heuristic(n_f, p_f[i], n_g, p_g[i])


# --- the compiled estimator: every technique an njit function (lightprobe's own have njit twins) -------------------
def _rows(lo, hi, sample, other_pdf, heuristic, is_bsdf, has_other, count, other_count, u, wo, normal, frame, position,
          material, environment, data, other_material, other_environment, other_data, wi, pdf, world, local, p_other,
          weight):  # fmt: skip
    """Rows [lo, hi) of one technique's ``count`` samples per point (row r: sample r // n of point r % n): the
    direction and pdf ``sample`` returns, the direction in both frames, the other technique's pdf there and the MIS
    weight (1 without another technique).  Each technique's context holds its own records (``_records``)."""
    n = wo.shape[0]
    wo, normal, frame, position = borrowed(wo), borrowed(normal), borrowed(frame), borrowed(position)
    material, environment, data = borrowed(material), borrowed(environment), borrowed(data)
    other_material, other_environment = borrowed(other_material), borrowed(other_environment)
    other_data = borrowed(other_data)
    for r in range(lo, hi):
        k = r % n
        ctx = JitContext(wo[k], normal[k], frame[k], position[k], material, environment, data)
        w, p = sample(u[r], ctx)
        x, y, z = w[0], w[1], w[2]
        wi[r, 0], wi[r, 1], wi[r, 2] = x, y, z
        pdf[r] = p
        if is_bsdf:
            local[r, 0], local[r, 1], local[r, 2] = x, y, z
            for j in range(3):
                world[r, j] = x * frame[k, 0, j] + y * frame[k, 1, j] + z * frame[k, 2, j]
        else:
            world[r, 0], world[r, 1], world[r, 2] = x, y, z
            for j in range(3):
                local[r, j] = frame[k, j, 0] * x + frame[k, j, 1] * y + frame[k, j, 2] * z
        if has_other:
            other = JitContext(wo[k], normal[k], frame[k], position[k], other_material, other_environment, other_data)
            q = other_pdf(world[r] if is_bsdf else local[r], other)
            p_other[r] = q
            weight[r] = heuristic(count, p, other_count, q)
        else:
            weight[r] = 1.0


# one body, inlined into the loop compiled for a user's functions (each run) and into the cached loops of
# lightprobe's own techniques (compiled once, so that lab:mis pays no compile per run)
_rows_inline = user_inline(_rows)
_technique_rows = _user_serial(_rows)


@jit
def _builtin_bsdf_rows(lo, hi, power, has_other, count, other_count, u, wo, normal, frame, position, material,
                       environment, data, other_material, other_environment, other_data, wi, pdf, world, local,
                       p_other, weight):  # fmt: skip
    """:func:`_rows` for lightprobe's BSDF sampling, against its map sampling under MIS."""
    if power:
        _rows_inline(lo, hi, builtin_bsdf_sample, builtin_env_pdf, power_weight, True, has_other, count, other_count,
                     u, wo, normal, frame, position, material, environment, data, other_material, other_environment,
                     other_data, wi, pdf, world, local, p_other, weight)  # fmt: skip
    else:
        _rows_inline(lo, hi, builtin_bsdf_sample, builtin_env_pdf, balance_weight, True, has_other, count, other_count,
                     u, wo, normal, frame, position, material, environment, data, other_material, other_environment,
                     other_data, wi, pdf, world, local, p_other, weight)  # fmt: skip


@jit
def _builtin_light_rows(lo, hi, power, has_other, count, other_count, u, wo, normal, frame, position, material,
                        environment, data, other_material, other_environment, other_data, wi, pdf, world, local,
                        p_other, weight):  # fmt: skip
    """:func:`_rows` for lightprobe's map sampling, against its BSDF sampling under MIS."""
    if power:
        _rows_inline(lo, hi, builtin_env_sample, builtin_bsdf_pdf, power_weight, False, has_other, count,
                     other_count, u, wo, normal, frame, position, material, environment, data, other_material,
                     other_environment, other_data, wi, pdf, world, local, p_other, weight)  # fmt: skip
    else:
        _rows_inline(lo, hi, builtin_env_sample, builtin_bsdf_pdf, balance_weight, False, has_other, count,
                     other_count, u, wo, normal, frame, position, material, environment, data, other_material,
                     other_environment, other_data, wi, pdf, world, local, p_other, weight)  # fmt: skip


@jit_parallel
def _first_invalid(wi, pdf, p_other, weight, has_other):
    """How many rows break the contract (a direction or pdf not finite, a pdf < 0, a non-unit direction with
    pdf > 0, the other pdf not finite or < 0, a weight outside [0, 1]); any, and the NumPy path names the first."""
    bad = 0
    for r in prange(pdf.shape[0]):
        x, y, z, p = wi[r, 0], wi[r, 1], wi[r, 2], pdf[r]
        wrong = not (np.isfinite(x) and np.isfinite(y) and np.isfinite(z) and np.isfinite(p)) or p < 0.0
        if not wrong and p > 0.0:
            wrong = abs(np.sqrt(x * x + y * y + z * z) - 1.0) > UNIT_TOLERANCE
        if has_other and not wrong:
            q, w = p_other[r], weight[r]
            wrong = not (np.isfinite(q) and q >= 0.0 and np.isfinite(w) and 0.0 <= w <= 1.0 + 1e-9)
        if wrong:
            bad += 1
    return bad


def _check_scene(scene) -> None:
    if scene.environment is None:
        raise TechniqueError(f"scene {scene.name!r}: user techniques need an environment map; this scene has none")
    emitting = len(scene.emitters) + len(scene.lights)
    if emitting:
        raise TechniqueError(
            f"scene {scene.name!r}: user techniques render scenes lit by an environment map alone (the exercise's "
            f"setting); this one has {emitting} other light(s): a light selector renders it (sel:FILE.py[:NAME], "
            "sel:bvh)"
        )
    require_untextured(scene, "user techniques")


class _Shader:
    """Everything one render needs between passes."""

    def __init__(self, scene, strategy: LabStrategy, settings: RenderSettings):
        self.scene = scene
        self.strategy = strategy
        self.settings = settings
        self.arrays = scene.compile()
        self.tracer = RayTracer(self.arrays)
        self.cam = scene.camera.kernel_array()
        self.origin = np.asarray(scene.camera.origin, dtype=np.float64)
        self.env = scene.environment
        self.materials = list(scene.materials.values())
        self.counts = strategy.counts(settings)
        self.heuristic = strategy.heuristic if strategy.heuristic is not None else settings.heuristic
        self.dims = [t.dimensions for t in strategy.techniques]
        self.sampler = SAMPLERS[settings.sampler]
        self.rays = 0  # shadow rays traced
        #: the render's clock, for its time limit (set by render_lab)
        self.clock = RenderClock(None)
        # every technique an njit function (or lightprobe's own) and the heuristic a name or an njit function: the
        # compiled estimator (_shade_compiled); otherwise the NumPy one (_shade)
        self.compiled = all(t.jit is not None for t in strategy.techniques) and (
            len(strategy.techniques) == 1 or isinstance(self.heuristic, str | Dispatcher)
        )

    def close(self):
        self.tracer.close()

    def values(self, pixels: np.ndarray, sample: int) -> np.ndarray:
        """Each pixel's value (N, 3) for one sample index."""
        n = pixels.shape[0]
        samples = np.full(n, sample, dtype=np.int64)
        seed = self.settings.seed
        jitter = sampler_batch(self.sampler, seed, pixels, samples, 2)
        dirs = camera_batch(self.cam, pixels, jitter)
        t, kind, index, prim, b1, b2 = self.tracer.intersect(np.broadcast_to(self.origin, dirs.shape), dirs)
        value = np.zeros((n, 3))
        miss = kind == MISS
        if miss.any():
            value[miss] = self.env.eval(dirs[miss])
        point, gnormal, error, frame, wo, material = shading_batch(
            self.arrays, kind, index, prim, b1, b2, t, self.origin, dirs
        )
        frame = frame.reshape(n, 3, 3)
        # each technique's numbers, (count, N, dims), its group of slots starting after the previous technique's
        numbers, first = [], 0
        for count, dims in zip(self.counts, self.dims, strict=True):
            numbers.append(technique_numbers(self.sampler, seed, pixels, sample, first, count, dims))
            first += count
        for m in np.unique(material[material >= 0]):
            rows = np.nonzero(material == m)[0]
            ctx = Context(wo[rows], frame[rows, 2], frame[rows], point[rows], self.materials[m], self.env)
            shade = self._shade_compiled if self.compiled else self._shade
            value[rows] += shade(ctx, [u[:, rows] for u in numbers], gnormal[rows], error[rows])
        return value

    def _records(self, technique, material) -> tuple:
        """The material and map records of a technique's context in the compiled estimator. lightprobe's own
        techniques get the material as its kernel block and the map with its kernel arrays, types defined once in
        the module, so that their njit twins are compiled once and cached, beside a user's technique too (a record
        type made at run time is not found in the cache: the twins compiled for 1.9 s on every run). A user's
        technique gets its material's named tuple and the map without lightprobe's kernel arrays, a context that
        compiles faster (``environment_record``, decisions.md 136)."""
        if technique.builtin:
            return KernelMaterial(material.kind, material.params), environment_record(self.env)
        return material_record(material), environment_record(self.env, kernel=False)

    def _shade_compiled(self, ctx: Context, numbers: list[np.ndarray], gnormal, error) -> np.ndarray:
        """:meth:`_shade` with every technique's njit functions called inside compiled loops, one sample at a time,
        and the rest of the estimator in the render core's compiled routines, in the same order of operations.
        A batch that breaks the techniques' contract (a raise, NaN, a negative pdf, ...) is shaded again by
        :meth:`_shade`, whose checks name the function, the check and the sample."""
        techniques = self.strategy.techniques
        n = len(ctx)
        out = np.zeros((n, 3))
        material = ctx.material
        # lightprobe's techniques alone, under a named heuristic, run their two cached loops
        builtin = all(t.builtin for t in techniques) and isinstance(self.heuristic, str)
        records = [self._records(t, material) for t in techniques]
        frame = np.ascontiguousarray(ctx.frame)
        wo = np.ascontiguousarray(ctx.wo)
        normal = np.ascontiguousarray(ctx.normal)
        position = np.ascontiguousarray(ctx.position)
        for t in techniques:
            if t.kind == "light":
                t.prepare(self.env)
        data = [t.data() for t in techniques]
        rays_before = self.rays
        for j, (tech, count) in enumerate(zip(techniques, self.counts, strict=True)):
            m = count * n
            u = np.ascontiguousarray(numbers[j].reshape(m, -1))
            has_other = len(techniques) == 2
            other = techniques[1 - j] if has_other else tech
            other_count = self.counts[1 - j] if has_other else count
            wi, pdf, world, local = np.empty((m, 3)), np.empty(m), np.empty((m, 3)), np.empty((m, 3))
            p_other, weight = np.zeros(m), np.empty(m)
            start = time.perf_counter()
            i = 1 - j if has_other else j  # the other technique (the same one alone)
            arrays = (float(count), float(other_count), u, wo, normal, frame, position, *records[j], data[j],
                      *records[i], data[i], wi, pdf, world, local, p_other, weight)  # fmt: skip
            try:
                if builtin:
                    loop = _builtin_bsdf_rows if tech.kind == "bsdf" else _builtin_light_rows
                    run_rows(loop, m, self.heuristic == "power", has_other, *arrays)
                else:
                    heuristic = HEURISTICS[self.heuristic] if isinstance(self.heuristic, str) else self.heuristic
                    functions = (tech.jit[0], other.jit[1], heuristic if has_other else HEURISTICS["balance"])
                    run_rows(_technique_rows, m, *functions, tech.kind == "bsdf", has_other, *arrays)
                failed = _first_invalid(wi, pdf, p_other, weight, has_other) > 0
            except Exception:  # the user's code raised: the NumPy path finds and names it
                failed = True
            if failed:
                self.rays = rays_before
                return self._shade(ctx, numbers, gnormal, error)
            elapsed_check(tech.label, "sample", start, max(t.time_limit for t in techniques), m)
            # compiled code cannot be stopped from outside (and a signal must not land in Numba's compiler, which
            # the first call runs): the render's time limit, like the technique's own, is looked at after the batch
            self.clock.seconds_left()
            self.rays += add_samples(out, ctx, count, local, world, pdf, weight, gnormal, error, self.tracer.occluded)
        return out

    def _shade(self, ctx: Context, numbers: list[np.ndarray], gnormal, error) -> np.ndarray:
        """The estimator of the module docstring at the points of ``ctx`` (one material), each technique called as
        NumPy once for all its samples of the batch, its checks naming the function, the check and the sample;
        ``numbers[t]`` holds technique t's random numbers, (count, N, dims) (``integrators.batch_estimator.shade``)."""

        def weight(n_f, p_f, n_g, p_g):
            return _weight(self.heuristic, n_f, p_f, n_g, p_g)

        out, rays = shade(ctx, self.strategy.techniques, self.counts, weight, numbers, gnormal, error,
                          self.tracer.occluded)  # fmt: skip
        self.rays += rays
        return out


def render_lab(scene, strategy, settings: RenderSettings | None = None, *, resume=None, progress=None) -> RenderResult:
    """Render ``settings.spp`` samples per pixel from ``settings.first_sample`` (continuing ``resume``, an
    :class:`Accumulator` at that count) with the techniques of ``strategy`` (a :class:`LabStrategy`; or a light
    selector's, :class:`~lightprobe.lab.light_render.SelectorStrategy`); ``settings.time_limit`` stops the
    render between passes, or stops a technique's call in flight at the limit (a compiled batch: after it) and drops
    its pass (Numba's compiling not counted); Ctrl-C keeps the passes done; ``progress(stats)`` after each pass (the
    render core's stats keys). See the module docstring."""
    from ..integrators.wavefront import resolve
    from .light_render import LightShader, SelectorStrategy, check_light_scene

    lights = isinstance(strategy, SelectorStrategy)
    (check_light_scene if lights else _check_scene)(scene)
    # the render core's plan: the settings checked and resolved as a render of the scene resolves them (the
    # laboratory's estimator takes spp samples in every pixel: no adaptive counts)
    settings = resolve(scene, (settings or RenderSettings()).uniform_unless_adaptive()).settings
    width, height = scene.camera.resolution
    acc = resume.copy() if resume is not None else Accumulator(width * height)
    first = settings.first_sample
    if resume is not None and (problem := resume.resume_problem(first)) is not None:
        raise TechniqueError(problem)
    shader = (LightShader if lights else _Shader)(scene, strategy, settings)
    start = time.perf_counter()
    stopped = interrupted = False
    pixels_all = np.arange(width * height, dtype=np.int64)
    done = 0
    pass_seconds = 0.0
    # the time limit bounds the whole render, not only the passes after the one in flight: a technique's call is
    # stopped at the limit however long its own limit (GuardedTechnique.clock), and the pass it was in is dropped
    clock = shader.clock = RenderClock(settings.time_limit)
    for technique in strategy.techniques:
        technique.clock = clock
    try:
        with clock:  # lightprobe's and Numba's compiling is not the render's time
            for sample in range(first, first + settings.spp):
                spent = clock.seconds_spent()
                if settings.time_limit is not None and done > 0 and spent + pass_seconds > settings.time_limit:
                    stopped = True
                    break
                values = np.empty((width * height, 3))
                for lo in range(0, pixels_all.size, BATCH):
                    block = pixels_all[lo : lo + BATCH]
                    values[lo : lo + BATCH] = shader.values(block, sample)
                acc.add(values)
                done += 1
                pass_seconds = clock.seconds_spent() - spent
                if progress is not None:
                    progress(_stats(settings, strategy, start, done, False, False, shader, acc))
    except KeyboardInterrupt:
        interrupted = True
    except _RenderTimeUp:  # the pass in flight is dropped (its pixels would have uneven counts)
        stopped = True
    except TechniqueError as exc:
        stats = _stats(settings, strategy, start, done, False, False, shader, acc)
        # what the render holds: the samples it continued and the passes it finished (compare's rounds continue
        # each other, and its message counts them all)
        kept = int(acc.count.min())
        partial = result_from(acc, width, height, stats) if kept else None
        raise LabRenderError(
            f"{exc} (during sample {first + done}; {kept} sample(s) per pixel kept)", partial
        ) from None
    finally:
        shader.close()
        for technique in strategy.techniques:
            technique.clock = None
    stats = _stats(settings, strategy, start, done, stopped, interrupted, shader, acc)
    return result_from(acc, width, height, stats)


def _stats(settings, strategy, start, done, stopped, interrupted, shader, acc) -> dict:
    """The render core's stats keys that apply (the CLI's progress bar, sidecar and summary read them)."""
    seconds = time.perf_counter() - start
    camera = done * acc.count.size
    return {
        "seconds": seconds,
        "spp": done,
        "spp_done": int(acc.count.min()),
        "spp_max": int(acc.count.max()),
        "passes": done,
        "camera_rays": camera,
        "samples_per_s": camera / max(seconds, 1e-9),
        "rays_per_s": (camera + shader.rays) / max(seconds, 1e-9),
        "nonfinite_samples": int(acc.nonfinite.sum()),
        "adaptive": False,
        "estimator": (
            "lightprobe.lab (a light selector)"
            if not strategy.techniques
            else f"lightprobe.lab (user techniques, {'compiled' if shader.compiled else 'NumPy'})"
        ),
        "strategy": strategy.label,
        "directions_per_sample": sum(strategy.counts(settings)),
        "stopped_by_time_limit": stopped,
        "interrupted": interrupted,
        "seed": settings.seed,
        "sampler": settings.sampler,
    }


# --- strategy tokens of `lightprobe compare` -------------------------------------------------------------------------
_TOKEN = re.compile(r"^(?P<mis>mis:)?(?P<specs>.+?\.py(?::\w+)?(?:\+.+?\.py(?::\w+)?)*)(?P<overrides>(?:/[^/]*)*)$")


#: lightprobe's own techniques through the laboratory's estimator: the render core's image, at the laboratory's
#: speed, for comparisons with user techniques at equal time
BUILTIN_TOKENS = {"lab:mis": ("bsdf", "light"), "lab:brdf": ("bsdf",), "lab:env": ("light",)}


#: a light selector's strategy (lab/light_render.py): ``sel:FILE.py[:NAME]`` or ``sel:`` and one of lightprobe's
_SELECTOR_TOKEN = re.compile(r"^sel:(?P<spec>.+?\.py(?::\w+)?|\w+)(?P<overrides>(?:/[^/]*)*)$")


def is_lab_token(token: str) -> bool:
    """Does a strategy token name a user technique (``FILE.py[:NAME]``, ``mis:FILE.py[:NAME][+FILE.py[:NAME]]``),
    lightprobe's techniques through the laboratory (``lab:mis``, ``lab:brdf``, ``lab:env``) or a light selector
    (``sel:FILE.py[:NAME]``, ``sel:bvh``)?"""
    token = token.strip()
    return ".py" in token or token.split("/")[0] in BUILTIN_TOKENS or token.startswith("sel:")


def parse_lab_token(token: str) -> tuple[LabStrategy, list[str]]:
    """The strategy of a token and its ``/key=value`` overrides. ``FILE.py[:NAME]``: the technique alone;
    ``mis:SPEC``: SPEC under MIS with lightprobe's technique of the other kind; ``mis:SPEC+SPEC``: a user BSDF
    technique and a user light technique under MIS."""
    from .light_render import SelectorStrategy
    from .selectors import load_selector
    from .techniques import builtin, load_technique

    if token.strip().startswith("sel:"):
        match = _SELECTOR_TOKEN.match(token.strip())
        if match is None:
            raise TechniqueError(f"strategy {token!r}: expected sel:FILE.py[:NAME] or sel:uniform, sel:power, sel:bvh")
        spec = match["spec"]
        selector = load_selector(spec) if ".py" in spec else spec
        return SelectorStrategy(selector), [part for part in match["overrides"].split("/") if part]
    name, *overrides = token.strip().split("/")
    if name in BUILTIN_TOKENS:
        return LabStrategy(tuple(builtin(kind) for kind in BUILTIN_TOKENS[name])), [o for o in overrides if o]
    match = _TOKEN.match(token.strip())
    if match is None:
        raise TechniqueError(f"strategy {token!r}: expected FILE.py[:NAME] or mis:FILE.py[:NAME][+FILE.py[:NAME]]")
    techniques = [load_technique(spec) for spec in match["specs"].split("+")]
    overrides = [part for part in match["overrides"].split("/") if part]
    if match["mis"]:
        if len(techniques) == 1:
            other = "light" if techniques[0].kind == "bsdf" else "bsdf"
            techniques = [techniques[0], builtin(other)] if other == "light" else [builtin(other), techniques[0]]
        elif sorted(t.kind for t in techniques) != ["bsdf", "light"]:
            kinds = ", ".join(f"{t.label} ({t.kind})" for t in techniques)
            raise TechniqueError(f"strategy {token!r}: MIS needs one BSDF and one light technique, got {kinds}")
    elif len(techniques) != 1:
        raise TechniqueError(f"strategy {token!r}: two techniques need the mis: prefix")
    return LabStrategy(tuple(techniques)), overrides
